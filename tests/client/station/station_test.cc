// `stevi station` against a real stevi-server on the synthetic rig, through its Foxglove WebSocket
// and its HTTP API (tests/testing/ws_client.h): each channel carries what the server streams, in
// the schema it advertises; previews are asked for only while somebody watches; the access token
// guards the socket and the API; bad flags are refused naming the problem.
#include "client/station/station.h"

#include <gmock/gmock.h>
#include <google/protobuf/util/message_differencer.h>
#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <set>
#include <thread>

#include "foxglove/CompressedImage.pb.h"
#include "foxglove/ImageAnnotations.pb.h"
#include "foxglove/LocationFix.pb.h"
#include "foxglove/SceneUpdate.pb.h"
#include "stevi/v1/station.pb.h"
#include "tests/server/server_process.h"
#include "tests/testing/data.h"
#include "tests/testing/ws_client.h"

namespace stevi {
namespace {

using namespace std::chrono_literals;
using ::testing::HasSubstr;
using testing::ServerProcess;
using testing::WsClient;
using testing::WsMessage;

constexpr auto kWait = 60s;
constexpr char kStationToken[] = "station-access-token-0123456789";

// The server's own stream, read by the test: the reference for what the channels carry.
class Reference {
 public:
  explicit Reference(const std::string& address) {
    client::ClientOptions options;
    options.address = address;
    client_ = std::make_unique<client::Client>(options);
    thread_ = std::thread([this] {
      client::StreamOptions stream;
      stream.reconnect = true;
      stream.persist_once_streaming = true;
      stream.max_reconnect_attempts = 0;
      (void)client_->StreamTracks(
          [this](const v1::TrackFrame& frame) {
            std::lock_guard lock(mu_);
            by_time_[frame.capture_unix_time_ns()] = frame;
            while (by_time_.size() > 3000) by_time_.erase(by_time_.begin());
            return true;
          },
          stream);
    });
  }
  ~Reference() {
    client_->Cancel();
    thread_.join();
  }
  std::optional<v1::TrackFrame> AtTime(int64_t unix_ns) const {
    std::lock_guard lock(mu_);
    const auto it = by_time_.find(unix_ns);
    if (it == by_time_.end()) return std::nullopt;
    return it->second;
  }
  client::Client& client() { return *client_; }

 private:
  std::unique_ptr<client::Client> client_;
  mutable std::mutex mu_;
  std::map<int64_t, v1::TrackFrame> by_time_;
  std::thread thread_;
};

int64_t Nanos(const google::protobuf::Timestamp& t) {
  return t.seconds() * 1'000'000'000 + t.nanos();
}

// A Foxglove client of the station: the channels it advertised, by topic.
struct FoxgloveSession {
  std::unique_ptr<WsClient> ws;
  std::map<std::string, nlohmann::json> channels;  // topic -> advertised channel
  nlohmann::json server_info;
  std::map<uint32_t, std::string> subscriptions;  // subscription id -> topic

  // Connects and reads serverInfo and the advertise; fails the test otherwise.
  void Open(int port, const std::string& path = "/") {
    std::string error;
    testing::WsOptions options;
    options.path = path;
    options.subprotocols = {"foxglove.sdk.v1", "foxglove.websocket.v1"};
    ws = WsClient::Connect("127.0.0.1", port, options, error);
    ASSERT_TRUE(ws != nullptr) << error;
    ASSERT_TRUE(ws->open()) << ws->status() << " " << ws->response_body();
    EXPECT_EQ(ws->subprotocol(), "foxglove.sdk.v1");
    while (channels.empty()) {
      std::optional<WsMessage> m = ws->Receive(kWait);
      ASSERT_TRUE(m && m->opcode == WsMessage::kText) << "no serverInfo and advertise";
      const nlohmann::json j = nlohmann::json::parse(m->payload);
      if (j["op"] == "serverInfo") server_info = j;
      if (j["op"] == "advertise") {
        for (const auto& c : j["channels"]) channels[c["topic"].get<std::string>()] = c;
      }
    }
  }
  void Subscribe(uint32_t id, const std::string& topic) {
    ASSERT_TRUE(channels.count(topic)) << topic << " is not advertised";
    subscriptions[id] = topic;
    const nlohmann::json op = {
        {"op", "subscribe"},
        {"subscriptions", {{{"id", id}, {"channelId", channels[topic]["id"]}}}}};
    ASSERT_TRUE(ws->SendText(op.dump()));
  }
  void Unsubscribe(uint32_t id) {
    ASSERT_TRUE(
        ws->SendText(nlohmann::json{{"op", "unsubscribe"}, {"subscriptionIds", {id}}}.dump()));
    subscriptions.erase(id);
  }
  // The next message data frame: its topic and payload (skipping JSON messages).
  std::optional<std::pair<std::string, std::string>> Next(std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      std::optional<WsMessage> m =
          ws->Receive(std::chrono::duration_cast<std::chrono::milliseconds>(
              deadline - std::chrono::steady_clock::now()));
      if (!m || m->opcode == WsMessage::kEnd || m->opcode == WsMessage::kClose) return std::nullopt;
      if (m->opcode != WsMessage::kBinary || m->payload.size() < 13 || m->payload[0] != 0x01) {
        continue;
      }
      uint32_t id = 0;
      for (int i = 0; i < 4; ++i)
        id |= static_cast<uint32_t>(static_cast<uint8_t>(m->payload[1 + i])) << (8 * i);
      const auto it = subscriptions.find(id);
      if (it == subscriptions.end()) continue;  // in flight before an unsubscribe
      return std::pair{it->second, m->payload.substr(13)};
    }
    return std::nullopt;
  }
};

class StationTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_NO_FATAL_FAILURE(server_.Start({}));
    reference_ = std::make_unique<Reference>(server_.address());
  }
  void StartStation(const std::string& access_token = "") {
    station::StationOptions options;
    options.servers = {server_.address()};
    options.web.listen = "127.0.0.1:0";
    options.web.access_token = access_token;
    std::string error;
    station_ = station::Station::Start(options, &error);
    ASSERT_TRUE(station_ != nullptr) << error;
  }
  // The server's preview subscribers, from its status.
  size_t PreviewSubscribers() {
    v1::GetStatusResponse status;
    EXPECT_TRUE(reference_->client().GetStatus(&status).ok());
    return status.preview_streams();
  }

  ServerProcess server_;
  std::unique_ptr<Reference> reference_;
  std::unique_ptr<station::Station> station_;
};

TEST_F(StationTest, EachChannelCarriesWhatTheServerStreamsInTheSchemaItAdvertises) {
  ASSERT_NO_FATAL_FAILURE(StartStation());
  FoxgloveSession s;
  ASSERT_NO_FATAL_FAILURE(s.Open(station_->port()));
  EXPECT_EQ(s.server_info["capabilities"], nlohmann::json::array());
  const std::map<std::string, std::string> expected_schemas = {
      {"/rig1/tracks", "stevi.v1.TrackFrame"},
      {"/rig1/status", "stevi.v1.StationRigStatus"},
      {"/rig1/image/annotated", "foxglove.CompressedImage"},
      {"/rig1/image/disparity", "foxglove.CompressedImage"},
      {"/rig1/image/left", "foxglove.CompressedImage"},
      {"/rig1/annotations", "foxglove.ImageAnnotations"},
      {"/rig1/scene", "foxglove.SceneUpdate"},
      {"/rig1/vehicle", "foxglove.LocationFix"}};
  for (const auto& [topic, schema] : expected_schemas) {
    ASSERT_TRUE(s.channels.count(topic)) << topic;
    EXPECT_EQ(s.channels[topic]["schemaName"], schema) << topic;
    EXPECT_EQ(s.channels[topic]["encoding"], "protobuf") << topic;
  }
  uint32_t id = 0;
  for (const std::string topic : {"/rig1/tracks", "/rig1/status", "/rig1/image/left",
                                  "/rig1/annotations", "/rig1/scene", "/rig1/vehicle"}) {
    ASSERT_NO_FATAL_FAILURE(s.Subscribe(id++, topic));
  }

  std::map<std::string, int> checked;
  double left_scale = 0;  // the left preview's pixels per TrackFrame pixel
  const auto enough = [&checked] {
    for (const std::string topic : {"/rig1/tracks", "/rig1/status", "/rig1/image/left",
                                    "/rig1/annotations", "/rig1/scene", "/rig1/vehicle"}) {
      if (checked[topic] < 5) return false;
    }
    return true;
  };
  int tracks_compared = 0;
  uint64_t status_frames = 0;  // the most track frames a status said the station received
  const auto deadline = std::chrono::steady_clock::now() + kWait;
  while (!enough() && std::chrono::steady_clock::now() < deadline) {
    std::optional<std::pair<std::string, std::string>> m = s.Next(kWait);
    ASSERT_TRUE(m) << "no message data";
    const auto& [topic, payload] = *m;
    if (topic == "/rig1/tracks") {
      v1::TrackFrame frame;
      ASSERT_TRUE(frame.ParseFromString(payload));
      const std::optional<v1::TrackFrame> ref = reference_->AtTime(frame.capture_unix_time_ns());
      if (!ref) continue;  // not (yet) in the reference's window
      v1::TrackFrame a = frame, b = *ref;
      a.clear_dropped_frames();  // per subscriber
      b.clear_dropped_frames();
      EXPECT_TRUE(google::protobuf::util::MessageDifferencer::Equals(a, b))
          << "frame " << frame.frame_id() << " differs from the server's";
      tracks_compared += frame.tracks_size();
    } else if (topic == "/rig1/status") {
      v1::StationRigStatus status;
      ASSERT_TRUE(status.ParseFromString(payload));
      EXPECT_EQ(status.rig(), "rig1");
      EXPECT_EQ(status.address(), server_.address());
      // Counted once the server is up, its source runs and the station has frames (a status
      // may come before any of these at first).
      if (status.connection() != v1::StationRigStatus::CONNECTION_UP ||
          status.server().source_state() != v1::SOURCE_STATE_RUNNING ||
          status.track_frames() == 0) {
        continue;
      }
      status_frames = std::max(status_frames, status.track_frames());
    } else if (topic == "/rig1/image/left") {
      foxglove::CompressedImage image;
      ASSERT_TRUE(image.ParseFromString(payload));
      EXPECT_EQ(image.format(), "jpeg");
      EXPECT_EQ(image.frame_id(), "rig1_camera");
      const cv::Mat decoded = cv::imdecode(
          std::vector<uchar>(image.data().begin(), image.data().end()), cv::IMREAD_UNCHANGED);
      ASSERT_FALSE(decoded.empty()) << "not a JPEG";
      EXPECT_LE(decoded.cols, 640);
      const std::optional<v1::TrackFrame> ref = reference_->AtTime(Nanos(image.timestamp()));
      if (ref) {
        left_scale = static_cast<double>(decoded.cols) / ref->image_width();
        EXPECT_NEAR(decoded.rows, ref->image_height() * left_scale, 1.0);
      }
    } else if (topic == "/rig1/annotations") {
      if (left_scale == 0) continue;  // its boxes are in the left preview's pixels
      foxglove::ImageAnnotations annotations;
      ASSERT_TRUE(annotations.ParseFromString(payload));
      if (annotations.points_size() == 0) continue;
      const std::optional<v1::TrackFrame> ref =
          reference_->AtTime(Nanos(annotations.points(0).timestamp()));
      if (!ref) continue;
      ASSERT_EQ(annotations.points_size(), ref->tracks_size());
      ASSERT_EQ(annotations.texts_size(), ref->tracks_size());
      for (int i = 0; i < ref->tracks_size(); ++i) {
        const v1::BoundingBox& box = ref->tracks(i).bbox();
        const foxglove::PointsAnnotation& p = annotations.points(i);
        EXPECT_EQ(p.type(), foxglove::PointsAnnotation::LINE_LOOP);
        ASSERT_EQ(p.points_size(), 4);
        EXPECT_NEAR(p.points(0).x(), box.x() * left_scale, 1e-6);
        EXPECT_NEAR(p.points(0).y(), box.y() * left_scale, 1e-6);
        EXPECT_NEAR(p.points(2).x(), (box.x() + box.width()) * left_scale, 1e-6);
        EXPECT_NEAR(p.points(2).y(), (box.y() + box.height()) * left_scale, 1e-6);
        EXPECT_THAT(annotations.texts(i).text(),
                    HasSubstr("#" + std::to_string(ref->tracks(i).track_id()) + " "));
      }
    } else if (topic == "/rig1/scene") {
      foxglove::SceneUpdate scene;
      ASSERT_TRUE(scene.ParseFromString(payload));
      ASSERT_EQ(scene.deletions_size(), 1);
      EXPECT_EQ(scene.deletions(0).type(), foxglove::SceneEntityDeletion::ALL);
      const std::optional<v1::TrackFrame> ref =
          reference_->AtTime(Nanos(scene.deletions(0).timestamp()));
      if (!ref) continue;
      ASSERT_EQ(scene.entities_size(), ref->tracks_size());
      for (int i = 0; i < ref->tracks_size(); ++i) {
        const foxglove::SceneEntity& e = scene.entities(i);
        EXPECT_EQ(e.id(), "track-" + std::to_string(ref->tracks(i).track_id()));
        EXPECT_EQ(e.frame_id(), "rig1_camera");
        ASSERT_EQ(e.cubes_size(), 1);
        EXPECT_DOUBLE_EQ(e.cubes(0).pose().position().z(), ref->tracks(i).position_cam().z_m());
      }
    } else if (topic == "/rig1/vehicle") {
      foxglove::LocationFix fix;
      ASSERT_TRUE(fix.ParseFromString(payload));
      EXPECT_EQ(fix.frame_id(), "rig1_vehicle");
      // The vehicle state of the frame it came with (the synthetic rig's pose at capture time).
      const std::optional<v1::TrackFrame> ref = reference_->AtTime(Nanos(fix.timestamp()));
      if (!ref) continue;
      EXPECT_DOUBLE_EQ(fix.latitude(), ref->vehicle().position().lat_deg());
      EXPECT_DOUBLE_EQ(fix.longitude(), ref->vehicle().position().lon_deg());
      EXPECT_DOUBLE_EQ(fix.altitude(), ref->vehicle().position().alt_m());
      if (ref->vehicle().position_sigma_horizontal_m() > 0) {
        ASSERT_EQ(fix.position_covariance_size(), 9);
        EXPECT_EQ(fix.position_covariance_type(), foxglove::LocationFix::DIAGONAL_KNOWN);
      } else {
        EXPECT_EQ(fix.position_covariance_type(), foxglove::LocationFix::UNKNOWN);
      }
    }
    ++checked[topic];
  }
  for (const auto& [topic, n] : checked) EXPECT_GE(n, 5) << topic;
  EXPECT_GT(tracks_compared, 0);
  EXPECT_GT(status_frames, 0u) << "no status counted the station's track frames";
  std::cout << "[ figures ] checked: tracks " << checked["/rig1/tracks"] << " frames ("
            << tracks_compared << " tracks equal to the server's), annotations "
            << checked["/rig1/annotations"] << ", scenes " << checked["/rig1/scene"] << ", fixes "
            << checked["/rig1/vehicle"] << ", left previews " << checked["/rig1/image/left"]
            << " (scale " << left_scale << "), status " << checked["/rig1/status"] << "\n";
}

// The station asks the server for previews only while a client subscribes to an image channel.
TEST_F(StationTest, PreviewsAreAskedForOnlyWhileSomebodyWatches) {
  ASSERT_NO_FATAL_FAILURE(StartStation());
  FoxgloveSession s;
  ASSERT_NO_FATAL_FAILURE(s.Open(station_->port()));
  ASSERT_NO_FATAL_FAILURE(s.Subscribe(1, "/rig1/tracks"));
  // Tracks flow, and no preview stream is open.
  for (int i = 0; i < 10; ++i) ASSERT_TRUE(s.Next(kWait)) << "no track frames";
  EXPECT_EQ(PreviewSubscribers(), 0u);
  ASSERT_NO_FATAL_FAILURE(s.Subscribe(2, "/rig1/image/disparity"));
  int images = 0;
  const auto deadline = std::chrono::steady_clock::now() + kWait;
  while (images < 3 && std::chrono::steady_clock::now() < deadline) {
    std::optional<std::pair<std::string, std::string>> m = s.Next(kWait);
    ASSERT_TRUE(m);
    images += m->first == "/rig1/image/disparity" ? 1 : 0;
  }
  ASSERT_EQ(images, 3);
  EXPECT_EQ(PreviewSubscribers(), 1u);
  // Unsubscribed: the station ends its preview stream (the server sees it go).
  ASSERT_NO_FATAL_FAILURE(s.Unsubscribe(2));
  size_t subscribers = 1;
  for (int i = 0; i < 600 && subscribers != 0; ++i) {
    ASSERT_TRUE(s.Next(kWait));  // paced by the track frames, about 10 Hz
    subscribers = PreviewSubscribers();
  }
  EXPECT_EQ(subscribers, 0u) << "the station kept its preview stream";
}

TEST_F(StationTest, TheAccessTokenGuardsTheSocketAndTheApiButNotThePage) {
  ASSERT_NO_FATAL_FAILURE(StartStation(kStationToken));
  const int port = station_->port();
  std::string error;
  const auto get = [&](const std::string& target, const std::string& token) {
    std::vector<std::pair<std::string, std::string>> headers;
    if (!token.empty()) headers.emplace_back("Authorization", "Bearer " + token);
    std::optional<testing::HttpReply> r =
        testing::HttpRequestOnce("127.0.0.1", port, "GET", target, headers, "", error);
    EXPECT_TRUE(r) << error;
    return r ? r->status : 0;
  };
  EXPECT_EQ(get("/", ""), 200) << "the page itself is open (it asks for the token)";
  EXPECT_EQ(get("/app.js", ""), 200);
  EXPECT_EQ(get("/api/rigs", ""), 401);
  EXPECT_EQ(get("/api/rigs", "wrong-token-wrong-token"), 403);
  EXPECT_EQ(get("/api/rigs", kStationToken), 200);

  testing::WsOptions options;
  options.subprotocols = {"foxglove.websocket.v1"};
  std::unique_ptr<WsClient> refused = WsClient::Connect("127.0.0.1", port, options, error);
  ASSERT_TRUE(refused) << error;
  EXPECT_FALSE(refused->open());
  EXPECT_EQ(refused->status(), 401);
  FoxgloveSession s;
  ASSERT_NO_FATAL_FAILURE(s.Open(port, std::string("/?token=") + kStationToken));
}

TEST_F(StationTest, TheApiPassesControlOnAndNamesTheBadField) {
  ASSERT_NO_FATAL_FAILURE(StartStation());
  const int port = station_->port();
  std::string error;
  std::optional<testing::HttpReply> r = testing::HttpRequestOnce(
      "127.0.0.1", port, "POST", "/api/rigs/rig1/config", {{"Content-Type", "application/json"}},
      R"({"matcher":{"block_matching":{"num_disparities":20}}})", error);
  ASSERT_TRUE(r) << error;
  EXPECT_EQ(r->status, 400);
  const nlohmann::json body = nlohmann::json::parse(r->body);
  EXPECT_EQ(body["code"], "INVALID_ARGUMENT");
  ASSERT_EQ(body["problems"].size(), 1u) << r->body;
  EXPECT_EQ(body["problems"][0]["field"], "matcher.block_matching.num_disparities");
  r = testing::HttpRequestOnce("127.0.0.1", port, "POST", "/api/rigs/rig1/config", {}, "{not json",
                               error);
  ASSERT_TRUE(r) << error;
  EXPECT_EQ(r->status, 400);
  EXPECT_THAT(r->body, HasSubstr("not a PipelineConfig"));
  r = testing::HttpRequestOnce("127.0.0.1", port, "POST", "/api/rigs/rig1/config", {},
                               R"({"algorithm":"ALGORITHM_STEVIS"})", error);
  ASSERT_TRUE(r) << error;
  EXPECT_EQ(r->status, 200) << r->body;
  v1::PipelineConfig active;
  ASSERT_TRUE(reference_->client().GetPipelineConfig(&active).ok());
  EXPECT_EQ(active.algorithm(), v1::ALGORITHM_STEVIS);
  r = testing::HttpRequestOnce("127.0.0.1", port, "GET", "/api/rigs/rig9/config", {}, "", error);
  ASSERT_TRUE(r) << error;
  EXPECT_EQ(r->status, 404);
  r = testing::HttpRequestOnce("127.0.0.1", port, "GET", "/leaflet/../../etc/passwd", {}, "",
                               error);
  ASSERT_TRUE(r) << error;
  EXPECT_EQ(r->status, 404);
}

// Long untrusted strings on every path the station parses: a 200-character calibration id (whose
// error message once went through std::regex, which recurses per character and overflowed the
// worker's stack: SIGSEGV), a long API path and a long static file path. Each gets its error; the
// station keeps serving.
TEST_F(StationTest, LongIdsAndPathsGetTheirErrorAndTheStationStaysUp) {
  ASSERT_NO_FATAL_FAILURE(StartStation());
  const int port = station_->port();
  std::string error;
  for (const size_t n : {100u, 200u, 5000u}) {
    const std::string id(n, 'x');
    std::optional<testing::HttpReply> r = testing::HttpRequestOnce(
        "127.0.0.1", port, "POST", "/api/rigs/rig1/calibrations/activate",
        {{"Content-Type", "application/json"}}, R"({"id": ")" + id + R"("})", error);
    ASSERT_TRUE(r) << n << ": " << error;
    EXPECT_GE(r->status, 400) << r->body;
    EXPECT_LT(r->status, 500) << r->body;
    r = testing::HttpRequestOnce("127.0.0.1", port, "GET", "/api/rigs/rig1/" + std::string(n, 'a'),
                                 {}, "", error);
    ASSERT_TRUE(r) << n << ": " << error;
    EXPECT_EQ(r->status, 404);
    r = testing::HttpRequestOnce("127.0.0.1", port, "GET",
                                 "/leaflet/" + std::string(n, 'b') + ".js", {}, "", error);
    ASSERT_TRUE(r) << n << ": " << error;
    EXPECT_EQ(r->status, 404);
  }
  const std::optional<testing::HttpReply> rigs =
      testing::HttpRequestOnce("127.0.0.1", port, "GET", "/api/rigs", {}, "", error);
  ASSERT_TRUE(rigs) << error;
  EXPECT_EQ(rigs->status, 200);
}

// The exports hold the georeferenced tracks the station received: the same tracks, as
// `stevi export` writes them.
TEST_F(StationTest, ExportsTheGeoreferencedTracksItReceived) {
  ASSERT_NO_FATAL_FAILURE(StartStation());
  FoxgloveSession s;
  ASSERT_NO_FATAL_FAILURE(s.Open(station_->port()));
  ASSERT_NO_FATAL_FAILURE(s.Subscribe(1, "/rig1/tracks"));
  // A frame on the socket was collected before it was published.
  std::set<uint64_t> confirmed_geo;  // tracks the exports must hold
  for (int i = 0; i < 20; ++i) {
    std::optional<std::pair<std::string, std::string>> m = s.Next(kWait);
    ASSERT_TRUE(m);
    v1::TrackFrame frame;
    ASSERT_TRUE(frame.ParseFromString(m->second));
    for (const v1::Track& t : frame.tracks()) {
      if (t.has_geodetic() && t.state() != v1::TRACK_STATE_TENTATIVE) {
        confirmed_geo.insert(t.track_id());
      }
    }
  }
  ASSERT_FALSE(confirmed_geo.empty()) << "no georeferenced confirmed track in 20 frames";
  std::string error;
  std::optional<testing::HttpReply> r = testing::HttpRequestOnce(
      "127.0.0.1", station_->port(), "GET", "/api/rigs/rig1/export.geojson", {}, "", error);
  ASSERT_TRUE(r) << error;
  ASSERT_EQ(r->status, 200);
  const nlohmann::json geojson = nlohmann::json::parse(r->body);
  EXPECT_EQ(geojson["type"], "FeatureCollection");
  std::set<uint64_t> exported;
  for (const auto& f : geojson["features"]) {
    exported.insert(f["properties"]["track_id"].get<uint64_t>());
  }
  // Every track seen is there; later frames may have added more.
  for (const uint64_t id : confirmed_geo) EXPECT_TRUE(exported.count(id)) << "track " << id;
  r = testing::HttpRequestOnce("127.0.0.1", station_->port(), "GET", "/api/rigs/rig1/export.kml",
                               {}, "", error);
  ASSERT_TRUE(r) << error;
  ASSERT_EQ(r->status, 200);
  EXPECT_THAT(r->body, HasSubstr("<kml"));
  size_t placemarks = 0;
  for (size_t at = r->body.find("<Placemark"); at != std::string::npos;
       at = r->body.find("<Placemark", at + 1)) {
    ++placemarks;
  }
  EXPECT_GE(placemarks, confirmed_geo.size());
}

// --export-points bounds each rig's export history: it fills up to the bound and stays there (the
// soak, tests/bench/soak.cc, lowers it to see the station's memory level off).
TEST_F(StationTest, TheExportHistoryKeepsTheNewestPointsUpToItsBound) {
  station::StationOptions options;
  options.servers = {server_.address()};
  options.web.listen = "127.0.0.1:0";
  options.export_points = 40;
  std::string error;
  station_ = station::Station::Start(options, &error);
  ASSERT_TRUE(station_ != nullptr) << error;
  const auto exported_points = [&] {
    std::string e;
    const std::optional<testing::HttpReply> r = testing::HttpRequestOnce(
        "127.0.0.1", station_->port(), "GET", "/api/rigs/rig1/export.geojson", {}, "", e);
    EXPECT_TRUE(r && r->status == 200) << e;
    uint64_t points = 0;
    if (!r) return points;
    const nlohmann::json geojson = nlohmann::json::parse(r->body);
    for (const auto& f : geojson["features"]) {
      points += f["properties"]["points"].get<uint64_t>();
    }
    return points;
  };
  // The synthetic rig gives several georeferenced confirmed tracks a frame: 40 points fill in a
  // few seconds; then the count stays at the bound while frames go on arriving.
  uint64_t points = 0;
  for (int i = 0; i < 600 && points < 40; ++i) {
    std::this_thread::sleep_for(100ms);
    points = exported_points();
  }
  EXPECT_EQ(points, 40u);
  std::this_thread::sleep_for(1s);
  EXPECT_EQ(exported_points(), 40u);
}

// Bytes the page's calls may carry that once took the station down, found by
// tests/fuzz/station_http, with no server behind the rig (127.0.0.1:1: nobody listens): a path that
// is not UTF-8 gets its 404 (its error's JSON threw, so it got 500), and an operator token that is
// not printable ASCII gets 400 naming it (gRPC aborted the whole station on it: "API misuse ...
// INVALID_METADATA").
TEST(StationApi, BadBytesInPathsAndOperatorTokensGetTheirErrorsAndTheStationStaysUp) {
  station::StationOptions options;
  options.servers = {"127.0.0.1:1"};
  options.web.listen = "127.0.0.1:0";
  std::string error;
  std::unique_ptr<station::Station> station = station::Station::Start(options, &error);
  ASSERT_TRUE(station != nullptr) << error;
  const int port = station->port();

  std::optional<testing::HttpReply> r =
      testing::HttpRequestOnce("127.0.0.1", port, "GET", "/api/rigs/rig1/%C3%28", {}, "", error);
  ASSERT_TRUE(r) << error;
  EXPECT_EQ(r->status, 404) << r->body;
  EXPECT_EQ(nlohmann::json::parse(r->body)["code"], "NOT_FOUND");
  station::HttpRequest get;
  get.method = "GET";
  get.path = "/api/rig\xc3/rig1/frobnicate";
  EXPECT_EQ(station->HandleHttp(get).status, 404);

  const std::pair<std::string, std::string> calls[] = {
      {"/api/rigs/rig1/config", R"({"algorithm":"ALGORITHM_STEVIS"})"},
      {"/api/rigs/rig1/calibrations/activate", R"({"id":"cal-000001"})"}};
  for (const auto& [path, body] : calls) {
    SCOPED_TRACE(path);
    r = testing::HttpRequestOnce(
        "127.0.0.1", port, "POST", path,
        {{"Content-Type", "application/json"}, {"X-Stevi-Operator-Token", "operator-\xc9-token"}},
        body, error);
    ASSERT_TRUE(r) << error;
    EXPECT_EQ(r->status, 400) << r->body;
    const nlohmann::json reply = nlohmann::json::parse(r->body);
    EXPECT_EQ(reply["code"], "INVALID_ARGUMENT");
    ASSERT_EQ(reply["problems"].size(), 1u) << r->body;
    EXPECT_EQ(reply["problems"][0]["field"], "operator_token");
    station::HttpRequest post;
    post.method = "POST";
    post.path = path;
    post.body = body;
    post.headers["x-stevi-operator-token"] = std::string(
        "tok\x01"
        "en");
    EXPECT_EQ(station->HandleHttp(post).status, 400);
  }
  r = testing::HttpRequestOnce("127.0.0.1", port, "GET", "/api/rigs", {}, "", error);
  ASSERT_TRUE(r) << error;
  EXPECT_EQ(r->status, 200);
}

TEST(StationCommand, RefusesUnsafeOrBadFlagsNamingTheProblem) {
  const std::string dir = testing::MakeTempDir("stevi-station-flags");
  std::ofstream(dir + "/short") << "short\n";
  std::ofstream(dir + "/bad.geojson") << R"({"type":"Nonsense"})";
  const struct {
    std::vector<std::string> args;
    std::string says;
  } cases[] = {
      {{"--listen", "0.0.0.0:0"}, "--token-file"},
      {{"--token-file", dir + "/short"}, "at least 16 characters"},
      {{"--token-file", dir + "/missing"}, "cannot read"},
      {{"--site", dir + "/bad.geojson"}, "unknown GeoJSON type"},
      {{"--preview-rate", "0"}, "--preview-rate"},
      {{"--max-clients", "0"}, "--max-clients"},
      {{"--export-points", "0"}, "--export-points"},
      {{"--server", ","}, "at least one"},
  };
  for (const auto& c : cases) {
    std::vector<std::string> argv = {testing::BinaryPath("stevi"), "station"};
    argv.insert(argv.end(), c.args.begin(), c.args.end());
    testing::Subprocess p(argv);
    const std::optional<int> code = p.Wait(30s);
    ASSERT_TRUE(code.has_value());
    EXPECT_EQ(*code, 2) << c.args[0];
    EXPECT_THAT(p.DrainStderr(), HasSubstr(c.says)) << c.args[0];
  }
}

}  // namespace
}  // namespace stevi
