// The ground station's page in a real browser (Debian's headless Chromium) against a real
// stevi-server on the synthetic rig and a real `stevi station`: the video changes, the table shows
// the tracks the server streams, the controls reach the server and show its errors, a stored
// calibration can be activated when none is active, the page's modules are served as JavaScript,
// and a server restart shows as down and then up again. Skips when Chromium is absent.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <map>
#include <mutex>
#include <regex>
#include <set>
#include <thread>

#include "client/lib/client.h"
#include "core/calibration/store.h"
#include "core/geometry/calibration_io.h"
#include "tests/server/server_process.h"
#include "tests/testing/chromium.h"
#include "tests/testing/data.h"
#include "tests/testing/subprocess.h"

namespace stevi {
namespace {

using namespace std::chrono_literals;
using testing::BinaryPath;
using testing::Browser;
using ::testing::HasSubstr;
using testing::ServerProcess;
using testing::Subprocess;

constexpr char kToken[] = "operator-token-for-the-browser-test";
constexpr auto kWait = 60s;

// A calibration store in `dir` (created) with calibrations but none active, as after `stevi
// calibrate` stored them and nobody activated one: cal-000001 passed its gates (the synthetic
// rig's own numbers: 640x480, f 700 px, baseline 0.6 m), cal-000002 failed them.
void WriteStoreWithoutActive(const std::string& dir) {
  Result<calibration::OpenedStore> opened = calibration::CalibrationStore::Open(dir);
  ASSERT_TRUE(opened.ok()) << opened.error().message;
  for (const bool passed : {true, false}) {
    calibration::CalibrationReport report;
    report.image_size = cv::Size(640, 480);
    report.pairs_given = 20;
    report.rms_px = passed ? 0.1 : 3.5;
    report.baseline_m = 0.6;
    report.passed = passed;
    const Result<calibration::CalibrationId> id = opened->store->Add(
        geometry::IdealCalibration(cv::Size(640, 480), 700, 0.6, 320, 240), report);
    ASSERT_TRUE(id.ok()) << id.error().message;
  }
  ASSERT_FALSE(opened->store->ActiveId().has_value());
}

// What the test itself receives from the server: the frames by id (the reference the page's
// table is checked against).
class FrameLog {
 public:
  void Add(const v1::TrackFrame& frame) {
    std::lock_guard lock(mu_);
    frames_[frame.frame_id()] = frame;
    while (frames_.size() > 2000) frames_.erase(frames_.begin());
  }
  std::optional<v1::TrackFrame> Find(uint64_t id) const {
    std::lock_guard lock(mu_);
    const auto it = frames_.find(id);
    if (it == frames_.end()) return std::nullopt;
    return it->second;
  }

 private:
  mutable std::mutex mu_;
  std::map<uint64_t, v1::TrackFrame> frames_;
};

class StationBrowser : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    std::string error;
    browser_ = Browser::Launch(&error).release();
    if (browser_ == nullptr) {
      skip_reason_ = "headless Chromium is not available: " + error;
      return;
    }
    token_dir_ = testing::MakeTempDir("stevi-station-token");
    std::ofstream(token_dir_ + "/token") << kToken << "\n";
    server_ = new ServerProcess();
    server_->Start({"--token-file", token_dir_ + "/token", "--allow-insecure"});
    if (::testing::Test::HasFatalFailure()) return;
    // A second rig, without a token, on another scene: the page has a panel per rig. Its data
    // directory holds calibrations, none of them active.
    const std::string second_data = token_dir_ + "/rig2-data";
    WriteStoreWithoutActive(second_data);
    if (::testing::Test::HasFatalFailure()) return;
    second_ = new ServerProcess();
    second_->Start({"--scene", "head_on", "--data-dir", second_data}, false);
    if (::testing::Test::HasFatalFailure()) return;
    // A site overlay: the outline of Pisa's runway 04R/22L around the synthetic rig's hover.
    std::ofstream(token_dir_ + "/site.geojson") << R"({"type": "FeatureCollection", "features": [
      {"type": "Feature", "properties": {"name": "runway 04R"}, "geometry": {"type": "Polygon",
       "coordinates": [[[10.3905, 43.6825], [10.3912, 43.6822], [10.4010, 43.6902],
                        [10.4003, 43.6905], [10.3905, 43.6825]]]}}]})";
    station_ = new Subprocess({BinaryPath("stevi"), "station", "--server",
                               server_->address() + "," + second_->address(), "--listen",
                               "127.0.0.1:0", "--site", token_dir_ + "/site.geojson"});
    const std::optional<std::string> line = station_->WaitForStdoutLine("serving", kWait);
    ASSERT_TRUE(line.has_value()) << "the station did not start: " << station_->DrainStderr();
    std::smatch m;
    ASSERT_TRUE(std::regex_search(*line, m, std::regex(R"(http://127\.0\.0\.1:(\d+)/)"))) << *line;
    url_ = "http://127.0.0.1:" + m[1].str() + "/";
    // The reference: the server's own stream, read by the test.
    client::ClientOptions options;
    options.address = server_->address();
    reference_client_ = new client::Client(options);
    reference_ = new FrameLog();
    reference_thread_ = new std::thread([] {
      client::StreamOptions stream;
      stream.reconnect = true;
      stream.persist_once_streaming = true;
      stream.max_reconnect_attempts = 0;
      (void)reference_client_->StreamTracks(
          [](const v1::TrackFrame& frame) {
            reference_->Add(frame);
            return true;
          },
          stream);
    });
    ASSERT_TRUE(browser_->Navigate(url_, kWait)) << url_;
  }

  static void TearDownTestSuite() {
    if (reference_client_ != nullptr) reference_client_->Cancel();
    if (reference_thread_ != nullptr) reference_thread_->join();
    delete reference_thread_;
    delete reference_client_;
    delete reference_;
    delete browser_;
    delete station_;
    delete second_;
    delete server_;
  }

  void SetUp() override {
    if (!skip_reason_.empty()) GTEST_SKIP() << skip_reason_;
    ASSERT_NE(server_, nullptr);
    ASSERT_NE(station_, nullptr);
  }

  // The value of a JS expression, failing the test on an exception.
  static nlohmann::json Eval(const std::string& expression) {
    Browser::Eval e = browser_->Evaluate(expression, kWait);
    EXPECT_TRUE(e.ok) << expression << ": " << e.error;
    return e.value;
  }

  static v1::PipelineConfig ServerConfig() {
    v1::PipelineConfig config;
    const grpc::Status status = reference_client_->GetPipelineConfig(&config);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return config;
  }

  static inline Browser* browser_ = nullptr;
  static inline ServerProcess* server_ = nullptr;
  static inline ServerProcess* second_ = nullptr;
  static inline Subprocess* station_ = nullptr;
  static inline client::Client* reference_client_ = nullptr;
  static inline FrameLog* reference_ = nullptr;
  static inline std::thread* reference_thread_ = nullptr;
  static inline std::string url_, token_dir_, skip_reason_;
};

// A hash of an <img>'s pixels, drawn onto a canvas in the page.
std::string PixelHash(const std::string& selector) {
  return R"((() => {
    const img = document.querySelector(')" +
         selector + R"(');
    if (!img || !img.complete || img.naturalWidth === 0) return null;
    const c = document.createElement('canvas');
    c.width = img.naturalWidth; c.height = img.naturalHeight;
    const g = c.getContext('2d'); g.drawImage(img, 0, 0);
    const d = g.getImageData(0, 0, c.width, c.height).data;
    let h = 2166136261 >>> 0;
    for (let i = 0; i < d.length; i += 7) { h ^= d[i]; h = Math.imul(h, 16777619) >>> 0; }
    return {hash: h, width: c.width, height: c.height, seq: Number(img.dataset.seq || 0)};
  })())";
}

// The pixel hash of the image once one with at least `min_seq` has finished loading. The
// page swaps an <img>'s source as each JPEG arrives, so "loaded" and "hashed" are one step in
// the page: the hash is taken by the same expression that finds the image complete.
nlohmann::json HashOnceLoaded(Browser& browser, const std::string& selector, int min_seq) {
  const std::string take = "((window.__stevi_hash = " + PixelHash(selector) +
                           ") !== null && window.__stevi_hash.seq >= " + std::to_string(min_seq) +
                           ")";
  if (!browser.WaitFor(take, kWait)) return nullptr;
  const Browser::Eval e = browser.Evaluate("window.__stevi_hash", kWait);
  EXPECT_TRUE(e.ok) << e.error;
  return e.value;
}

TEST_F(StationBrowser, TheVideoAndTheDisparityViewChange) {
  for (const std::string kind : {"annotated", "disparity"}) {
    const std::string selector =
        "section.rig[data-rig=\"rig1\"] img.video[data-kind=\"" + kind + "\"]";
    const nlohmann::json first = HashOnceLoaded(*browser_, selector, 2);
    ASSERT_TRUE(first.is_object()) << kind << ": no image arrived and loaded";
    EXPECT_GT(first["width"].get<int>(), 100) << kind;
    // Three images later the pixels differ: the synthetic scene moves.
    const nlohmann::json later = HashOnceLoaded(*browser_, selector, first["seq"].get<int>() + 3);
    ASSERT_TRUE(later.is_object()) << kind << ": three more images did not arrive";
    EXPECT_NE(first["hash"], later["hash"]) << kind << ": the pictures did not change";
    std::cout << "[ figures ] " << kind << ": " << later["width"] << "x" << later["height"]
              << " JPEG, seq " << first["seq"] << " -> " << later["seq"] << ", pixels changed\n";
  }
}

TEST_F(StationBrowser, TheTableShowsTheTracksTheServerStreams) {
  int compared = 0, rows_checked = 0;
  uint64_t last_frame = 0;
  for (int round = 0; round < 100 && compared < 8; ++round) {
    // The next frame the table shows that has rows.
    ASSERT_TRUE(browser_->WaitFor(
        "(() => { const t = document.querySelector('section.rig[data-rig=\"rig1\"] "
        "table.tracks'); return t && Number(t.dataset.frameId) > " +
            std::to_string(last_frame) + " && t.querySelectorAll('tbody tr').length > 0; })()",
        kWait));
    const nlohmann::json table = Eval(R"((() => {
      const t = document.querySelector('section.rig[data-rig="rig1"] table.tracks');
      return {frame: Number(t.dataset.frameId),
              rows: [...t.querySelectorAll('tbody tr')].map(r => ({
                id: Number(r.dataset.trackId),
                range: Number(r.querySelector('td.range').dataset.rangeM)}))};
    })())");
    last_frame = table["frame"].get<uint64_t>();
    const std::optional<v1::TrackFrame> frame = reference_->Find(last_frame);
    if (!frame) continue;  // the reference stream dropped this one; take the next
    std::map<uint64_t, double> expected;
    for (const v1::Track& t : frame->tracks()) expected[t.track_id()] = t.range_m();
    std::map<uint64_t, double> shown;
    for (const auto& row : table["rows"]) shown[row["id"].get<uint64_t>()] = row["range"];
    ASSERT_EQ(shown.size(), expected.size()) << "frame " << last_frame;
    for (const auto& [id, range] : expected) {
      ASSERT_TRUE(shown.count(id)) << "frame " << last_frame << ": track " << id << " missing";
      EXPECT_NEAR(shown[id], range, 1e-6) << "frame " << last_frame << " track " << id;
      ++rows_checked;
    }
    ++compared;
  }
  EXPECT_GE(compared, 8);
  std::cout << "[ figures ] the table matched the server's stream on " << compared << " frames, "
            << rows_checked << " rows by id and range\n";
}

// What the rig's controls show: the selected algorithm and the result and error lines, for a
// failure's message.
std::string ControlMessages(Browser& browser, const std::string& rig) {
  const Browser::Eval e = browser.Evaluate(
      "[...document.querySelectorAll('" + rig + "select.algorithm, " + rig + ".control-result, " +
          rig + "div.config-error, " + rig +
          "span.field-error')].map(e => (e.className || e.tagName) + ': ' + (e.value ?? '') + ' ' "
          "+ e.textContent).join(' | ')",
      kWait);
  return e.ok ? e.value.dump() : e.error;
}

TEST_F(StationBrowser, ControlsReachTheServerAndShowItsErrorsBesideTheField) {
  const std::string rig = "section.rig[data-rig=\"rig1\"] ";
  // The editor is built from the server's config.
  ASSERT_TRUE(
      browser_->WaitFor("!!document.querySelector('" + rig +
                            "input[data-field=\"matcher.block_matching.num_disparities\"]')",
                        kWait));
  const v1::PipelineConfig before = ServerConfig();
  const v1::Algorithm target =
      before.algorithm() == v1::ALGORITHM_STEVIE ? v1::ALGORITHM_STEVIS : v1::ALGORITHM_STEVIE;
  const std::string target_name = v1::Algorithm_Name(target);

  // Without the operator token the server refuses, and the page says so.
  Eval(
      "(() => { const t = document.querySelector('#operator-token'); t.value = ''; "
      "t.dispatchEvent(new Event('input')); t.dispatchEvent(new Event('change')); })()");
  Eval("(() => { const s = document.querySelector('" + rig + "select.algorithm'); s.value = '" +
       target_name + "'; s.dispatchEvent(new Event('change')); document.querySelector('" + rig +
       "button.apply-algorithm').click(); })()");
  // The refusal shows where the page puts a control's error (its message names the code).
  ASSERT_TRUE(browser_->WaitFor(
      "[...document.querySelectorAll('" + rig + "span.field-error[data-field=\"algorithm\"], " +
          rig + "div.config-error, " + rig +
          ".control-result')].some(e => /UNAUTHENTICATED/.test(e.textContent))",
      kWait));
  EXPECT_EQ(ServerConfig().algorithm(), before.algorithm());

  // With it, the switch reaches the server.
  Eval(std::string("(() => { const t = document.querySelector('#operator-token'); t.value = '") +
       kToken +
       "'; t.dispatchEvent(new Event('input')); t.dispatchEvent(new Event('change')); })()");
  Eval("document.querySelector('" + rig + "button.apply-algorithm').click()");
  bool switched = false;
  for (int i = 0; i < 600 && !switched; ++i) {
    // Each round waits for the page to have shown a new frame, so this is paced by the stream.
    switched = ServerConfig().algorithm() == target;
    if (!switched) {
      ASSERT_TRUE(browser_->WaitFor("window.stevi.rigs.rig1.lastFrame.algorithm === " +
                                        std::to_string(static_cast<int>(target)),
                                    kWait))
          << "the page says: " << ControlMessages(*browser_, rig);
    }
  }
  EXPECT_TRUE(switched) << "the server's algorithm is not " << target_name;
  ASSERT_TRUE(browser_->WaitFor(
      "window.stevi.rigs.rig1.lastFrame.algorithm === " + std::to_string(static_cast<int>(target)),
      kWait))
      << "the stream the page shows did not follow the switch";

  // A bad value: the server's error beside the field, and the server's config unchanged.
  const std::string field = "matcher.block_matching.num_disparities";
  Eval("(() => { const i = document.querySelector('" + rig + "input[data-field=\"" + field +
       "\"]'); i.value = '20'; i.dispatchEvent(new Event('input')); "
       "i.dispatchEvent(new Event('change')); document.querySelector('" +
       rig + "button.apply-config').click(); })()");
  const std::string error_el =
      "document.querySelector('" + rig + "span.field-error[data-field=\"" + field + "\"]')";
  ASSERT_TRUE(browser_->WaitFor("(" + error_el + "?.textContent || '').length > 0", kWait))
      << "no error beside the field";
  const std::string shown = Eval(error_el + ".textContent").get<std::string>();
  EXPECT_THAT(shown, HasSubstr("16")) << shown;  // "... a multiple of 16 ..." as the server says
  EXPECT_EQ(ServerConfig().matcher().block_matching().num_disparities(),
            before.matcher().block_matching().num_disparities());
  std::cout << "[ figures ] error shown beside " << field << ": \"" << shown << "\"\n";

  // Put the algorithm back for the other tests.
  v1::PipelineConfig restore;
  restore.set_algorithm(before.algorithm());
  client::ClientOptions options;
  options.address = server_->address();
  options.bearer_token = kToken;
  client::Client operator_client(options);
  v1::PipelineConfig active;
  ASSERT_TRUE(operator_client.SetPipelineConfig(restore, &active).ok());
}

TEST_F(StationBrowser, ASnapshotAndTheCalibrationsComeFromTheServer) {
  const std::string rig = "section.rig[data-rig=\"rig1\"] ";
  // The calibrations list shows what the server lists.
  v1::ListCalibrationsResponse list;
  ASSERT_TRUE(reference_client_->ListCalibrations(&list).ok());
  ASSERT_TRUE(browser_->WaitFor("document.querySelectorAll('" + rig +
                                    "div.calibrations button.activate-calibration').length >= " +
                                    std::to_string(list.calibrations_size()),
                                kWait));
  // The snapshot endpoint gives the server's annotated PNG.
  const nlohmann::json png = Eval(
      "fetch('/api/rigs/rig1/snapshot?kind=annotated').then(async r => ({status: r.status, "
      "type: r.headers.get('content-type'), size: (await r.arrayBuffer()).byteLength}))");
  EXPECT_EQ(png["status"], 200);
  EXPECT_EQ(png["type"], "image/png");
  EXPECT_GT(png["size"].get<int>(), 1000);
}

// With calibrations stored and none active (rig2's), a stored calibration that passed can be
// activated from the page: only the active calibration's button is disabled.
TEST_F(StationBrowser, WithNoActiveCalibrationOneCanBeActivated) {
  client::ClientOptions options;
  options.address = second_->address();
  client::Client rig2_client(options);
  v1::ListCalibrationsResponse list;
  ASSERT_TRUE(rig2_client.ListCalibrations(&list).ok());
  ASSERT_EQ(list.calibrations_size(), 2);
  ASSERT_EQ(list.active_id(), "") << "the seeded store should have no active calibration";

  const std::string rig2 = "section.rig[data-rig=\"rig2\"] ";
  const std::string button =
      "document.querySelector('" + rig2 +
      "div.calibrations button.activate-calibration[data-id=\"cal-000001\"]')";
  ASSERT_TRUE(browser_->WaitFor("!!" + button, kWait)) << "rig2's calibrations are not listed";
  const nlohmann::json shown =
      Eval("({disabled: " + button + ".disabled, text: " + button + ".textContent})");
  ASSERT_EQ(shown["disabled"], false)
      << "no calibration is active, yet cal-000001 cannot be activated: " << shown.dump();
  EXPECT_EQ(shown["text"], "activate") << shown.dump();

  // And activating it works: the server has it active, the page shows it so.
  Eval(button + ".click()");
  ASSERT_TRUE(
      browser_->WaitFor("(() => { const b = " + button +
                            "; return !!b && b.disabled && b.textContent === 'active'; })()",
                        kWait))
      << "the page does not show cal-000001 as active";
  ASSERT_TRUE(rig2_client.ListCalibrations(&list).ok());
  EXPECT_EQ(list.active_id(), "cal-000001");
}

// The map draws the --site overlay (in the local metres around the vehicle) and the tracks'
// geodetic positions.
TEST_F(StationBrowser, TheMapDrawsTheSiteAndTheTracks) {
  const std::string map = "section.rig[data-rig=\"rig1\"] div.map";
  ASSERT_TRUE(browser_->WaitFor("document.querySelector('" + map +
                                    "')?.dataset.geo === 'ok' && document.querySelectorAll('" +
                                    map + " path[stroke=\"#a371f7\"]').length >= 1",
                                kWait))
      << "no site overlay on the map";
  ASSERT_TRUE(browser_->WaitFor(
      "document.querySelectorAll('" + map + " [data-track-id]').length >= 1", kWait))
      << "no track on the map";
}

TEST_F(StationBrowser, EachRigHasItsOwnPanel) {
  const std::string rig2 = "section.rig[data-rig=\"rig2\"] ";
  ASSERT_TRUE(browser_->WaitFor("document.querySelector('" + rig2 +
                                    ".rig-state')?.dataset.state === 'up' && "
                                    "document.querySelectorAll('" +
                                    rig2 +
                                    "table.tracks tbody tr').length > 0 && Number("
                                    "document.querySelector('" +
                                    rig2 +
                                    "img.video[data-kind=\"annotated\"]')?.dataset.seq || 0) >= 2",
                                kWait));
  const nlohmann::json address =
      Eval("document.querySelector('" + rig2 + ".rig-address').textContent");
  EXPECT_THAT(address.get<std::string>(), HasSubstr(second_->address()));
  // The README's picture: both rigs up, with video and tracks.
  if (const char* shot = std::getenv("STEVI_STATION_SCREENSHOT")) {
    EXPECT_TRUE(browser_->Screenshot(shot));
  }
}

// The page's scripts are ES modules (app.js imports the others), which a browser runs only when
// they are served as JavaScript: each script the page loaded answers as text/javascript.
TEST_F(StationBrowser, TheScriptsAreServedAsJavaScript) {
  const nlohmann::json scripts = Eval(R"(Promise.all(performance.getEntriesByType('resource')
      .map(e => new URL(e.name)).filter(u => u.pathname.endsWith('.js') &&
                                             !u.pathname.startsWith('/leaflet/'))
      .map(u => fetch(u).then(r => ({path: u.pathname, status: r.status,
                                     type: r.headers.get('content-type')})))))");
  ASSERT_TRUE(scripts.is_array()) << scripts.dump();
  std::set<std::string> paths;
  for (const auto& script : scripts) {
    const std::string path = script["path"].get<std::string>();
    paths.insert(path);
    EXPECT_EQ(script["status"], 200) << path;
    EXPECT_THAT(script["type"].get<std::string>(), ::testing::StartsWith("text/javascript"))
        << path;
  }
  EXPECT_TRUE(paths.count("/app.js") && paths.count("/protobuf.js")) << scripts.dump();
  EXPECT_GT(paths.size(), 2u) << "app.js imported no module: " << scripts.dump();
}

// Last: the restart.
TEST_F(StationBrowser, AServerRestartShowsAsDownThenUp) {
  const std::string state = "document.querySelector('section.rig[data-rig=\"rig1\"] .rig-state')";
  ASSERT_TRUE(browser_->WaitFor(state + "?.dataset.state === 'up'", kWait));
  const auto t0 = std::chrono::steady_clock::now();
  server_->process()->Signal(SIGTERM);
  ASSERT_TRUE(browser_->WaitFor(state + ".dataset.state === 'down'", kWait))
      << "the page did not show the server as down";
  const auto t_down = std::chrono::steady_clock::now();
  EXPECT_EQ(Eval("document.querySelector('section.rig[data-rig=\"rig2\"] .rig-state')"
                 ".dataset.state"),
            "up")
      << "the other rig is not affected";
  ASSERT_NO_FATAL_FAILURE(server_->Restart());
  const auto t_restarted = std::chrono::steady_clock::now();
  ASSERT_TRUE(browser_->WaitFor(state + ".dataset.state === 'up'", kWait))
      << "the page did not show the server as back";
  const auto t_up = std::chrono::steady_clock::now();
  // And the video and the tracks flow again.
  const int seq = Eval(
                      "Number(document.querySelector('section.rig[data-rig=\"rig1\"] "
                      "img.video[data-kind=\"annotated\"]').dataset.seq)")
                      .get<int>();
  ASSERT_TRUE(
      browser_->WaitFor("Number(document.querySelector('section.rig[data-rig=\"rig1\"] "
                        "img.video[data-kind=\"annotated\"]').dataset.seq) > " +
                            std::to_string(seq + 2),
                        kWait));
  const auto ms = [](auto d) {
    return std::chrono::duration_cast<std::chrono::milliseconds>(d).count();
  };
  std::cout << "[ figures ] restart: shown down " << ms(t_down - t0) << " ms after SIGTERM; up "
            << ms(t_up - t_restarted) << " ms after the server said serving\n";
  // The page's own errors and uncaught exceptions (the HTTP errors it asked for, such as the
  // refusals above, are the network log's and do not count).
  for (const std::string& e : browser_->ConsoleErrors()) {
    if (e.rfind("log.network:", 0) != 0) ADD_FAILURE() << "page error: " << e;
  }
}

}  // namespace
}  // namespace stevi
