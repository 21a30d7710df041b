// Fault tests of stevi-server, the real binary as a child process on 127.0.0.1: garbage on the
// port, half-open connections, clients cancelling mid-stream, randomised out-of-range requests,
// a corrupt calibration store and a full disk while recording. After each fault the server must
// still be up (a new client gets frames, GetStatus works) and nothing must be lost (the active
// pipeline config and the calibration list are as before).
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>

#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <climits>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <mutex>
#include <random>
#include <regex>
#include <set>
#include <thread>

#include "client/lib/client.h"
#include "core/calibration/store.h"
#include "core/geometry/calibration_io.h"
#include "stevi/v1/obstacle_service.pb.h"
#include "tests/server/load_helpers.h"
#include "tests/server/server_process.h"
#include "tests/testing/data.h"
#include "tests/testing/subprocess.h"

namespace stevi {
namespace {

namespace fs = std::filesystem;
namespace pb = google::protobuf;
using namespace std::chrono_literals;
using testing::Clock;
using ::testing::HasSubstr;

constexpr char kFps[] = "15";

std::string RandomBytes(std::mt19937& rng, size_t n) {
  std::string out(n, '\0');
  for (char& c : out) c = static_cast<char>(rng() & 0xff);
  return out;
}

void WriteFile(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << bytes;
  ASSERT_TRUE(out.good()) << path;
}

// A calibration store in `dir` holding one good calibration, cal-000001 (the synthetic rig's own
// numbers: 640x480, f 700 px, baseline 0.6 m), active.
void WriteGoodStore(const std::string& dir) {
  Result<calibration::OpenedStore> opened = calibration::CalibrationStore::Open(dir);
  ASSERT_TRUE(opened.ok()) << opened.error().message;
  calibration::CalibrationReport report;
  report.image_size = cv::Size(640, 480);
  report.pairs_given = 20;  // the per-pair details are not needed here
  report.rms_px = 0.1;
  report.baseline_m = 0.6;
  report.passed = true;
  Result<calibration::CalibrationId> id = opened->store->Add(
      geometry::IdealCalibration(cv::Size(640, 480), 700, 0.6, 320, 240), report);
  ASSERT_TRUE(id.ok()) << id.error().message;
  ASSERT_EQ(id->Name(), "cal-000001");
  const Status active = opened->store->Activate(*id);
  ASSERT_TRUE(active.ok()) << active.error().message;
}

// True while the child has not exited (drains its pipes a moment on the way).
bool Alive(testing::Subprocess& process, std::string* why) {
  const std::optional<int> code = process.Wait(5ms);
  if (!code.has_value()) return true;  // still running (or died by a signal: see below)
  *why = "exited with code " + std::to_string(*code) + "; stderr:\n" + process.DrainStderr();
  return false;
}

class FaultTest : public ::testing::Test {
 protected:
  // Reads what the server wrote so far, so that it never blocks on a full stderr pipe.
  void Drain() { (void)server_.process()->Wait(1ms); }

  // A server on a data directory holding the good store, inside a sandbox folder of its own.
  void StartServer() {
    sandbox_ = testing::MakeTempDir("stevi-fault");
    data_dir_ = sandbox_ + "/data";
    ASSERT_NO_FATAL_FAILURE(WriteGoodStore(data_dir_));
    ASSERT_NO_FATAL_FAILURE(server_.Start({"--fps", kFps, "--data-dir", data_dir_}, false));
    client_ = testing::MakeClient(server_.address());
    baseline_ = testing::ReadState(*client_);
    ASSERT_EQ(baseline_.calibrations.calibrations_size(), 1);
    ASSERT_EQ(baseline_.calibrations.active_id(), "cal-000001");
    v1::GetStatusResponse status;
    ASSERT_TRUE(client_->GetStatus(&status).ok());
    ASSERT_EQ(status.calibration_id(), "cal-000001");
    // The faults are aimed at a running server: wait for its first frame (on a loaded machine the
    // source can still be starting a second after the port opens).
    grpc::Status streamed;
    ASSERT_EQ(testing::ReceiveFrames(server_.address(), 1, 60s, &streamed).size(), 1u)
        << "no first frame: " << streamed.error_message();
  }

  void SetUp() override { ASSERT_NO_FATAL_FAILURE(StartServer()); }

  // The server is up, a new client gets consecutive frames, and nothing was lost.
  void ExpectServing(const std::string& after) {
    SCOPED_TRACE("after " + after);
    std::string why;
    ASSERT_TRUE(Alive(*server_.process(), &why)) << "the server died: " << why;
    grpc::Status streamed;
    const std::vector<v1::TrackFrame> frames =
        testing::ReceiveFrames(server_.address(), 3, 30s, &streamed);
    ASSERT_EQ(frames.size(), 3u) << "no frames for a new client: " << streamed.error_message();
    for (size_t i = 1; i < frames.size(); ++i) {
      EXPECT_EQ(frames[i].frame_id(), frames[i - 1].frame_id() + 1);
    }
    // Asked after the frames arrived, so "running" is the state to expect, not "starting".
    std::unique_ptr<client::Client> fresh = testing::MakeClient(server_.address());
    v1::GetStatusResponse status;
    const grpc::Status got = fresh->GetStatus(&status);
    ASSERT_TRUE(got.ok()) << "GetStatus: " << got.error_message() << "; server stderr:\n"
                          << server_.process()->DrainStderr();
    EXPECT_EQ(status.source_state(), v1::SOURCE_STATE_RUNNING);
    testing::ExpectSameState(baseline_, testing::ReadState(*fresh), after);
  }

  std::string sandbox_, data_dir_;
  testing::ServerProcess server_;
  std::unique_ptr<client::Client> client_;
  testing::ServerState baseline_;
};

// ---------------------------------------------------------------------------------------------
// Garbage on the port.
// ---------------------------------------------------------------------------------------------

constexpr char kPreface[] = "PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n";  // 24 bytes

// An HTTP/2 frame header: 24-bit length, type, flags, 31-bit stream id.
std::string FrameHeader(uint32_t length, uint8_t type, uint8_t flags, uint32_t stream) {
  std::string h(9, '\0');
  h[0] = static_cast<char>((length >> 16) & 0xff);
  h[1] = static_cast<char>((length >> 8) & 0xff);
  h[2] = static_cast<char>(length & 0xff);
  h[3] = static_cast<char>(type);
  h[4] = static_cast<char>(flags);
  h[5] = static_cast<char>((stream >> 24) & 0x7f);
  h[6] = static_cast<char>((stream >> 16) & 0xff);
  h[7] = static_cast<char>((stream >> 8) & 0xff);
  h[8] = static_cast<char>(stream & 0xff);
  return h;
}

TEST_F(FaultTest, GarbageBytesOnThePort) {
  const int port = testing::PortOf(server_.address());
  std::mt19937 rng(20240611);
  struct Kind {
    std::string name;
    std::function<std::string()> bytes;
    bool server_must_close;  // a protocol error the server detects: it closes the connection
  };
  const std::string preface(kPreface, 24);
  const std::vector<Kind> kinds = {
      {"random bytes", [&] { return RandomBytes(rng, 1 + rng() % 65536); }, true},
      {"HTTP/1.1 request",
       [] {
         return std::string(
             "GET /stevi.v1.ObstacleService/GetStatus HTTP/1.1\r\nHost: 127.0.0.1\r\n"
             "User-Agent: fault-test\r\nAccept: */*\r\n\r\n");
       },
       true},
      {"truncated HTTP/2 preface", [&] { return preface.substr(0, 1 + rng() % 23); }, false},
      {"preface then random frames", [&] { return preface + RandomBytes(rng, 1 + rng() % 4096); },
       true},
      {"preface, settings, headers with garbage HPACK",
       [&] {
         const std::string hpack = RandomBytes(rng, 1 + rng() % 200);
         return preface + FrameHeader(0, 0x4, 0, 0) +
                FrameHeader(static_cast<uint32_t>(hpack.size()), 0x1, 0x4, 1) + hpack;
       },
       false},
      {"preface then a 16 MiB frame header",
       [&] {
         return preface + FrameHeader(0, 0x4, 0, 0) + FrameHeader(0xffffff, 0x0, 0, 1) +
                RandomBytes(rng, 1024);
       },
       true},
  };
  std::map<std::string, int> closed_by_server, sent;
  for (int round = 0; round < 8; ++round) {
    for (const Kind& kind : kinds) {
      const int fd = testing::ConnectTcp(port, 10s);
      ASSERT_GE(fd, 0) << "cannot connect to the server's port";
      testing::SendAll(fd, kind.bytes());
      ++sent[kind.name];
      if (kind.server_must_close) {
        // The server detects the protocol error and closes: wait for that (bounded).
        if (testing::ReadUntilClosed(fd)) ++closed_by_server[kind.name];
      }
      ::close(fd);
    }
    // Between rounds: the server answers a real call at once.
    Drain();
    v1::GetStatusResponse status;
    ASSERT_TRUE(client_->GetStatus(&status).ok()) << "round " << round;
  }
  for (const Kind& kind : kinds) {
    if (kind.server_must_close) {
      EXPECT_EQ(closed_by_server[kind.name], sent[kind.name])
          << kind.name << ": the server kept some of these connections open for 10 s";
    }
    std::printf(
        "garbage: %-48s x%d%s\n", kind.name.c_str(), sent[kind.name],
        kind.server_must_close
            ? (", closed by the server " + std::to_string(closed_by_server[kind.name])).c_str()
            : "");
  }
  ASSERT_NO_FATAL_FAILURE(ExpectServing("garbage bytes"));
}

// ---------------------------------------------------------------------------------------------
// Half-open connections.
// ---------------------------------------------------------------------------------------------

TEST_F(FaultTest, HalfOpenConnectionsDoNotBlockRealClients) {
  const int port = testing::PortOf(server_.address());
  constexpr int kSilent = 50;
  constexpr int kPrefaceOnly = 10;
  std::vector<int> fds;
  for (int i = 0; i < kSilent + kPrefaceOnly; ++i) {
    const int fd = testing::ConnectTcp(port);
    ASSERT_GE(fd, 0) << "connection " << i;
    // The last few speak the preface and then nothing (an HTTP/2 connection with no stream).
    if (i >= kSilent) testing::SendAll(fd, std::string(kPreface, 24));
    fds.push_back(fd);
  }
  // While they are open: a real client streams, calls and changes nothing.
  const Clock::time_point t0 = Clock::now();
  grpc::Status streamed;
  const std::vector<v1::TrackFrame> frames =
      testing::ReceiveFrames(server_.address(), 15, 30s, &streamed);
  const double stream_s = testing::Seconds(Clock::now() - t0);
  ASSERT_EQ(frames.size(), 15u) << streamed.error_message();
  for (size_t i = 1; i < frames.size(); ++i)
    EXPECT_EQ(frames[i].frame_id(), frames[i - 1].frame_id() + 1);
  for (int i = 0; i < 20; ++i) {
    v1::GetStatusResponse status;
    ASSERT_TRUE(client_->GetStatus(&status).ok());
  }
  ASSERT_NO_FATAL_FAILURE(ExpectServing("half-open connections (still open)"));
  // How many silent connections the server still holds (it may have sent its SETTINGS frame on
  // them: data to read is fine, only EOF or an error means closed). Reported, not asserted: a
  // server may close idle connections that never spoke.
  int still_open = 0;
  for (int i = 0; i < kSilent; ++i) {
    char c;
    const ssize_t n = ::recv(fds[i], &c, 1, MSG_DONTWAIT | MSG_PEEK);
    if (n > 0 || (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK))) ++still_open;
  }
  for (const int fd : fds) ::close(fd);
  std::printf(
      "half-open: %d silent + %d preface-only connections; 15 frames streamed in %.2f s "
      "meanwhile; %d silent ones still open before we closed them\n",
      kSilent, kPrefaceOnly, stream_s, still_open);
  ASSERT_NO_FATAL_FAILURE(ExpectServing("half-open connections (closed)"));
}

// ---------------------------------------------------------------------------------------------
// Clients cancelling mid-stream.
// ---------------------------------------------------------------------------------------------

TEST_F(FaultTest, ClientsCancellingMidStream) {
  constexpr int kThreads = 4;
  constexpr int kLibraryCycles = 15;  // per thread: client::Client::Cancel from another thread
  constexpr int kRawCycles = 10;      // per thread: ClientContext::TryCancel while in Read()
  std::atomic<int> library_ok{0}, raw_cancelled{0}, finished_workers{0};
  std::mutex failures_mu;
  std::vector<std::string> failures;
  const auto fail = [&](const std::string& what) {
    std::lock_guard lock(failures_mu);
    failures.push_back(what);
  };
  const std::string address = server_.address();
  std::vector<std::thread> workers;
  for (int t = 0; t < kThreads; ++t) {
    workers.emplace_back([&, t] {
      std::mt19937 rng(500 + t);
      for (int i = 0; i < kLibraryCycles; ++i) {
        // The library's Cancel() from this thread while StreamTracks() runs on another, after a
        // random number of frames (1..3).
        std::unique_ptr<client::Client> c = testing::MakeClient(address);
        const uint64_t k = 1 + rng() % 3;
        testing::StreamCount count;
        grpc::Status status;
        std::thread streaming([&] {
          status = c->StreamTracks([&](const v1::TrackFrame&) {
            count.Add();
            return true;
          });
          count.End();
        });
        const bool reached = count.WaitFor(k, 30s) >= k;
        c->Cancel();
        streaming.join();
        if (!reached) fail("library cycle: no " + std::to_string(k) + " frames within 30 s");
        if (!status.ok()) fail("library cycle: StreamTracks returned " + status.error_message());
        if (reached && status.ok()) ++library_ok;
      }
      for (int i = 0; i < kRawCycles; ++i) {
        // TryCancel from this thread while another is blocked in Read().
        std::shared_ptr<grpc::Channel> channel = testing::PrivateChannel(address);
        std::unique_ptr<v1::ObstacleService::Stub> stub = v1::ObstacleService::NewStub(channel);
        grpc::ClientContext context;
        context.set_deadline(std::chrono::system_clock::now() + 30s);
        const uint64_t k = 1 + rng() % 3;
        testing::StreamCount count;
        grpc::Status status;
        std::thread reading([&] {
          std::unique_ptr<grpc::ClientReader<v1::TrackFrame>> reader =
              stub->StreamTracks(&context, v1::StreamTracksRequest());
          v1::TrackFrame frame;
          while (reader->Read(&frame)) count.Add();
          status = reader->Finish();
          count.End();
        });
        count.WaitFor(k, 30s);
        context.TryCancel();
        reading.join();
        const uint64_t got = count.frames();
        if (got < k) fail("raw cycle: only " + std::to_string(got) + " frames");
        if (status.error_code() != grpc::StatusCode::CANCELLED) {
          fail("raw cycle: " + client::StatusCodeName(status.error_code()) + " " +
               status.error_message());
        } else {
          ++raw_cancelled;
        }
      }
      ++finished_workers;
    });
  }
  // Meanwhile keep the server's stderr drained; the workers' waits are all bounded.
  while (finished_workers.load() < kThreads) Drain();
  for (auto& w : workers) w.join();
  EXPECT_THAT(failures, ::testing::IsEmpty());
  EXPECT_EQ(library_ok.load(), kThreads * kLibraryCycles);
  EXPECT_EQ(raw_cancelled.load(), kThreads * kRawCycles);
  // Every subscription of the cancelled streams is gone (bounded wait on the server's report).
  v1::GetStatusResponse status;
  EXPECT_TRUE(testing::WaitForStatus(
      *client_, [](const v1::GetStatusResponse& s) { return s.subscribers_size() == 0; }, 10s,
      &status))
      << status.subscribers_size() << " subscribers left";
  std::printf("cancel: %d library Cancel() cycles, %d raw TryCancel() cycles, all ended cleanly\n",
              library_ok.load(), raw_cancelled.load());
  ASSERT_NO_FATAL_FAILURE(ExpectServing("cancelled streams"));
}

// ---------------------------------------------------------------------------------------------
// Randomised out-of-range requests.
// ---------------------------------------------------------------------------------------------

// Fills `m` (a PipelineConfig or one of its sub-messages) by reflection: each scalar field with
// probability `p`, with a value that is either extreme (0, -1, INT_MIN/MAX, NaN, inf, huge, an
// unknown enum number, ...) or, with probability `plausible`, near the active value in `base`.
class ConfigFuzzer {
 public:
  explicit ConfigFuzzer(uint32_t seed) : rng_(seed) {}

  void Fill(pb::Message& m, const pb::Message& base, double p, double plausible,
            const std::string& prefix, std::vector<std::string>& set_paths) {
    const pb::Descriptor* d = m.GetDescriptor();
    const pb::Reflection* r = m.GetReflection();
    const pb::Reflection* br = base.GetReflection();
    for (int i = 0; i < d->field_count(); ++i) {
      const pb::FieldDescriptor* f = d->field(i);
      const std::string path = prefix + f->name();
      if (f->cpp_type() == pb::FieldDescriptor::CPPTYPE_MESSAGE) {
        if (f->is_repeated()) continue;
        Fill(*r->MutableMessage(&m, f), br->GetMessage(base, f), p, plausible, path + ".",
             set_paths);
        continue;
      }
      if (!Chance(p)) continue;
      const bool near = Chance(plausible);
      if (f->is_repeated()) {
        const int n = static_cast<int>(rng_() % 7);
        for (int k = 0; k < n; ++k) {
          if (f->cpp_type() == pb::FieldDescriptor::CPPTYPE_INT32) {
            r->AddInt32(&m, f, near ? static_cast<int32_t>(rng_() % 9) : Int32(0));
          } else if (f->cpp_type() == pb::FieldDescriptor::CPPTYPE_DOUBLE) {
            r->AddDouble(&m, f, Double(0));
          } else if (f->cpp_type() == pb::FieldDescriptor::CPPTYPE_STRING) {
            r->AddString(&m, f, String());
          }
        }
        if (n > 0) set_paths.push_back(path);
        continue;
      }
      switch (f->cpp_type()) {
        case pb::FieldDescriptor::CPPTYPE_INT32: {
          const int32_t b = br->GetInt32(base, f);
          r->SetInt32(&m, f, near ? Near(b) : Int32(b));
          break;
        }
        case pb::FieldDescriptor::CPPTYPE_INT64:
          r->SetInt64(&m, f, near ? br->GetInt64(base, f) : Int64());
          break;
        case pb::FieldDescriptor::CPPTYPE_UINT32:
          r->SetUInt32(&m, f,
                       near ? br->GetUInt32(base, f) + static_cast<uint32_t>(rng_() % 3)
                            : static_cast<uint32_t>(Int64()));
          break;
        case pb::FieldDescriptor::CPPTYPE_UINT64:
          r->SetUInt64(&m, f, near ? br->GetUInt64(base, f) : static_cast<uint64_t>(Int64()));
          break;
        case pb::FieldDescriptor::CPPTYPE_DOUBLE: {
          const double b = br->GetDouble(base, f);
          r->SetDouble(&m, f, near ? NearDouble(b) : Double(b));
          break;
        }
        case pb::FieldDescriptor::CPPTYPE_FLOAT:
          r->SetFloat(&m, f, static_cast<float>(Double(br->GetFloat(base, f))));
          break;
        case pb::FieldDescriptor::CPPTYPE_BOOL: r->SetBool(&m, f, Chance(0.5)); break;
        case pb::FieldDescriptor::CPPTYPE_ENUM: {
          const pb::EnumDescriptor* e = f->enum_type();
          if (near || Chance(0.5)) {
            r->SetEnumValue(&m, f, e->value(static_cast<int>(rng_() % e->value_count()))->number());
          } else {
            static const int32_t kOdd[] = {-1, 7, 99, INT_MIN, INT_MAX, -100000};
            r->SetEnumValue(&m, f, kOdd[rng_() % std::size(kOdd)]);
          }
          break;
        }
        case pb::FieldDescriptor::CPPTYPE_STRING: r->SetString(&m, f, String()); break;
        default: continue;
      }
      set_paths.push_back(path);
    }
  }

  std::mt19937& rng() { return rng_; }
  bool Chance(double p) { return std::uniform_real_distribution<double>(0, 1)(rng_) < p; }

  std::string String() {
    static const std::vector<std::string> kOdd = {
        "",     "../../etc/passwd", std::string(3000, 'x'),        "\xc3\xa9t\xc3\xa9",
        "a\nb", "%s%n%x",           std::string("nul\0inside", 10)};
    if (Chance(0.5)) return kOdd[rng_() % kOdd.size()];
    std::string s(rng_() % 40, ' ');
    for (char& c : s) c = static_cast<char>(32 + rng_() % 95);
    return s;
  }

 private:
  int32_t Int32(int32_t base) {
    static const int32_t kOdd[] = {0,
                                   -1,
                                   1,
                                   2,
                                   3,
                                   4,
                                   5,
                                   7,
                                   15,
                                   16,
                                   17,
                                   63,
                                   64,
                                   100,
                                   101,
                                   255,
                                   256,
                                   1000,
                                   65535,
                                   1 << 20,
                                   INT_MAX,
                                   INT_MAX - 1,
                                   INT_MAX & ~15,
                                   INT_MIN,
                                   INT_MIN + 1,
                                   -16};
    switch (rng_() % 4) {
      case 0: return static_cast<int32_t>(rng_());
      case 1:  // wraps as the wire would; a signed overflow here was UB (UBSan found it)
        return static_cast<int32_t>(static_cast<uint32_t>(base) * 1000u);
      default: return kOdd[rng_() % std::size(kOdd)];
    }
  }
  int32_t Near(int32_t base) {
    static const int32_t kDelta[] = {0, 0, 1, -1, 2, -2, 16, -16};
    return base + kDelta[rng_() % std::size(kDelta)];
  }
  int64_t Int64() {
    static const int64_t kOdd[] = {0, -1, 1, INT64_MAX, INT64_MIN, INT_MAX, int64_t{1} << 40};
    return kOdd[rng_() % std::size(kOdd)];
  }
  double Double(double base) {
    static const double kOdd[] = {0.0,
                                  -0.0,
                                  -1.0,
                                  1.0,
                                  0.5,
                                  2.0,
                                  1e-300,
                                  std::numeric_limits<double>::denorm_min(),
                                  1e300,
                                  -1e300,
                                  std::numeric_limits<double>::max(),
                                  std::numeric_limits<double>::lowest(),
                                  std::numeric_limits<double>::quiet_NaN(),
                                  -std::numeric_limits<double>::quiet_NaN(),
                                  std::numeric_limits<double>::infinity(),
                                  -std::numeric_limits<double>::infinity(),
                                  1e9,
                                  -1e9};
    switch (rng_() % 4) {
      case 0:
        return std::ldexp(std::uniform_real_distribution<double>(-1, 1)(rng_),
                          static_cast<int>(rng_() % 2100) - 1050);
      case 1: return base * 1e6;
      default: return kOdd[rng_() % std::size(kOdd)];
    }
  }
  double NearDouble(double base) {
    static const double kFactor[] = {1.0, 1.0, 0.5, 0.9, 1.1, 2.0};
    return base * kFactor[rng_() % std::size(kFactor)] + (Chance(0.2) ? 1.0 : 0.0);
  }

  std::mt19937 rng_;
};

// "a.b.c" (optionally "a.b[2]") names a field of `d`, nested messages followed.
bool IsFieldPath(const pb::Descriptor* d, const std::string& path) {
  std::stringstream parts(path);
  std::string part;
  const pb::FieldDescriptor* f = nullptr;
  while (std::getline(parts, part, '.')) {
    if (d == nullptr) return false;
    if (const size_t bracket = part.find('['); bracket != std::string::npos) part.resize(bracket);
    f = d->FindFieldByName(part);
    if (f == nullptr) return false;
    d = f->message_type();
  }
  return f != nullptr;
}

// Splits an INVALID_ARGUMENT message into its problems ("field: problem"), dropping a truncated
// last one.
std::vector<std::string> Problems(const std::string& message) {
  std::vector<std::string> out;
  size_t start = 0;
  while (start <= message.size()) {
    const size_t end = message.find("; ", start);
    out.push_back(
        message.substr(start, end == std::string::npos ? std::string::npos : end - start));
    if (end == std::string::npos) break;
    start = end + 2;
  }
  if (!out.empty() && out.back().find("(truncated)") != std::string::npos) out.pop_back();
  return out;
}

bool HasNaN(const pb::Message& m) {
  const pb::Descriptor* d = m.GetDescriptor();
  const pb::Reflection* r = m.GetReflection();
  for (int i = 0; i < d->field_count(); ++i) {
    const pb::FieldDescriptor* f = d->field(i);
    if (f->is_repeated()) continue;
    if (f->cpp_type() == pb::FieldDescriptor::CPPTYPE_MESSAGE) {
      if (r->HasField(m, f) && HasNaN(r->GetMessage(m, f))) return true;
    } else if (f->cpp_type() == pb::FieldDescriptor::CPPTYPE_DOUBLE) {
      if (std::isnan(r->GetDouble(m, f))) return true;
    }
  }
  return false;
}

TEST_F(FaultTest, RandomisedOutOfRangePipelineConfigs) {
  constexpr int kRequests = 300;
  ConfigFuzzer fuzzer(4242);
  int applied = 0, refused = 0, applied_with_inf = 0;
  std::set<std::string> named_fields;
  v1::PipelineConfig active = baseline_.config;
  for (int i = 0; i < kRequests; ++i) {
    SCOPED_TRACE("request " + std::to_string(i));
    v1::PipelineConfig update;
    std::vector<std::string> set_paths;
    // A field or two (mostly plausible values), a few fields, or every field (mostly extreme).
    const int mode = static_cast<int>(fuzzer.rng()() % 10);
    if (mode < 4) {
      while (set_paths.empty()) {
        update.Clear();
        fuzzer.Fill(update, active, 0.02, 0.6, "", set_paths);
      }
    } else if (mode < 8) {
      fuzzer.Fill(update, active, 0.15, 0.4, "", set_paths);
    } else {
      fuzzer.Fill(update, active, 1.0, 0.2, "", set_paths);
    }
    Drain();
    v1::PipelineConfig response;
    const grpc::Status status = client_->SetPipelineConfig(update, &response);
    v1::PipelineConfig now;
    const grpc::Status got = client_->GetPipelineConfig(&now);
    if (!got.ok()) {
      std::string why;
      ASSERT_TRUE(Alive(*server_.process(), &why))
          << "the server died on " << update.ShortDebugString() << ": " << why;
      FAIL() << "GetPipelineConfig failed: " << got.error_message();
    }
    if (status.ok()) {
      ++applied;
      EXPECT_EQ(now.SerializeAsString(), response.SerializeAsString())
          << "the active config is not the one SetPipelineConfig returned";
      // What is active re-validates: setting it again succeeds and changes nothing.
      v1::PipelineConfig again;
      const grpc::Status revalidated = client_->SetPipelineConfig(now, &again);
      EXPECT_TRUE(revalidated.ok())
          << "the active config " << now.ShortDebugString() << " (after applying "
          << update.ShortDebugString() << ") does not re-validate: " << revalidated.error_message();
      EXPECT_EQ(again.SerializeAsString(), now.SerializeAsString());
      EXPECT_FALSE(HasNaN(now)) << "NaN accepted into the active config from "
                                << update.ShortDebugString() << ": " << now.ShortDebugString();
      if (now.ShortDebugString().find("inf") != std::string::npos) ++applied_with_inf;
      active = now;
    } else {
      EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT)
          << client::StatusCodeName(status.error_code()) << " " << status.error_message() << " for "
          << update.ShortDebugString();
      if (status.error_code() != grpc::StatusCode::INVALID_ARGUMENT) {
        std::string why;
        ASSERT_TRUE(Alive(*server_.process(), &why)) << why;
      }
      ++refused;
      // Each problem names a field of PipelineConfig.
      for (const std::string& problem : Problems(status.error_message())) {
        const std::string field = problem.substr(0, problem.find(':'));
        EXPECT_TRUE(IsFieldPath(v1::PipelineConfig::descriptor(), field))
            << "the problem \"" << problem
            << "\" does not name a PipelineConfig field (message: " << status.error_message()
            << ")";
        named_fields.insert(field);
      }
      EXPECT_EQ(now.SerializeAsString(), active.SerializeAsString())
          << "a refused config changed the active one";
    }
    if (i % 50 == 49) {
      // The pipeline keeps streaming under whatever valid config is active.
      grpc::Status streamed;
      const std::vector<v1::TrackFrame> frames =
          testing::ReceiveFrames(server_.address(), 2, 60s, &streamed);
      ASSERT_EQ(frames.size(), 2u) << "no frames with the active config "
                                   << active.ShortDebugString() << ": " << streamed.error_message();
    }
  }
  // The original config comes back, whole.
  v1::PipelineConfig restored;
  const grpc::Status restore = client_->SetPipelineConfig(baseline_.config, &restored);
  ASSERT_TRUE(restore.ok()) << restore.error_message();
  EXPECT_EQ(restored.SerializeAsString(), baseline_.config.SerializeAsString());
  std::printf(
      "config fuzz: %d requests, %d applied (%d with an infinity), %d refused naming %zu "
      "distinct fields\n",
      kRequests, applied, applied_with_inf, refused, named_fields.size());
  EXPECT_GT(applied, kRequests / 20) << "the fuzzer hardly ever produced a valid config";
  EXPECT_GT(refused, kRequests / 4);
  ASSERT_NO_FATAL_FAILURE(ExpectServing("randomised pipeline configs"));
}

// StreamTracks with random min_score, GetCalibration with random ids, StartRecording with random
// names: each valid one works, each invalid one is INVALID_ARGUMENT (or NOT_FOUND for an unknown
// calibration), and no directory appears outside DATA_DIR/recordings.
TEST_F(FaultTest, RandomisedStreamCalibrationAndRecordingRequests) {
  ConfigFuzzer fuzzer(777);
  std::mt19937& rng = fuzzer.rng();

  // StreamTracks: min_score.
  const std::vector<double> scores = {0.0,
                                      1.0,
                                      0.5,
                                      -0.0,
                                      -1e-300,
                                      1.0000001,
                                      -1,
                                      std::numeric_limits<double>::quiet_NaN(),
                                      std::numeric_limits<double>::infinity(),
                                      -std::numeric_limits<double>::infinity(),
                                      1e308,
                                      std::numeric_limits<double>::denorm_min()};
  int streams_ok = 0, streams_refused = 0;
  for (int i = 0; i < 24; ++i) {
    const double score = i < static_cast<int>(scores.size())
                             ? scores[i]
                             : std::uniform_real_distribution<double>(-2, 3)(rng);
    v1::StreamTracksRequest request;
    request.set_min_score(score);
    request.set_confirmed_only(rng() % 2 == 0);
    grpc::Status status;
    const std::vector<v1::TrackFrame> frames =
        testing::ReceiveFrames(server_.address(), 1, 30s, &status, request);
    if (score >= 0.0 && score <= 1.0) {
      EXPECT_EQ(frames.size(), 1u) << "min_score " << score << ": " << status.error_message();
      for (const v1::TrackFrame& f : frames) {
        for (const v1::Track& t : f.tracks()) EXPECT_GE(t.score(), score);
      }
      ++streams_ok;
    } else {
      EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << "min_score " << score;
      EXPECT_THAT(status.error_message(), HasSubstr("min_score"));
      ++streams_refused;
    }
  }

  // GetCalibration: random ids.
  std::vector<std::string> ids = {"cal-000001",
                                  "cal-1",
                                  "cal-0000000000001",
                                  "cal-000002",
                                  "cal-999999999999999",
                                  "cal-9999999999999999",
                                  "cal-",
                                  "cal--1",
                                  "cal-+1",
                                  "CAL-000001",
                                  "cal-000001.yaml",
                                  "../active",
                                  "/etc/passwd",
                                  "active",
                                  "",
                                  std::string(100000, '9'),
                                  std::string("cal-0\0", 6),
                                  "cal-00000１"};
  for (int i = 0; i < 60; ++i) {
    std::string id = fuzzer.String();  // printable ASCII or a valid UTF-8 oddity (proto3 strings)
    if (rng() % 2 == 0) {
      id = "cal-" + std::to_string(static_cast<int64_t>(rng()) - 1000);
      if (rng() % 2 == 0) id.push_back(static_cast<char>(32 + rng() % 95));
    }
    ids.push_back(id);
  }
  std::map<std::string, int> calibration_codes;
  for (const std::string& id : ids) {
    Drain();
    v1::CalibrationRecord record;
    const grpc::Status status = client_->GetCalibration(id, &record);
    calibration_codes[client::StatusCodeName(status.error_code())]++;
    const std::optional<calibration::CalibrationId> parsed = calibration::CalibrationId::Parse(id);
    if (parsed && parsed->value == 1) {
      EXPECT_TRUE(status.ok()) << "'" << id << "': " << status.error_message();
      EXPECT_EQ(record.summary().calibration_id(), "cal-000001");
    } else if (parsed) {
      EXPECT_EQ(status.error_code(), grpc::StatusCode::NOT_FOUND)
          << "'" << id << "': " << status.error_message();
    } else {
      EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT)
          << "'" << id.substr(0, 80) << "': " << status.error_message();
      EXPECT_THAT(status.error_message(), HasSubstr("calibration_id"));
    }
  }

  // StartRecording: random names and limits.
  const std::string escape_abs = sandbox_ + "/absolute-escape";
  std::vector<std::string> bad_names = {"..",
                                        ".",
                                        "../escape",
                                        "../../escape-2",
                                        "a/b",
                                        "/abs",
                                        escape_abs,
                                        ".hidden",
                                        std::string(65, 'n'),
                                        "with space",
                                        "tab\there",
                                        "new\nline",
                                        std::string("nul\0x", 5),
                                        "\xc3\xa9t\xc3\xa9",
                                        "back\\slash",
                                        "~",
                                        "$(touch x)",
                                        "%2e%2e",
                                        "a:b",
                                        "*"};
  const std::string allowed = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789-_.";
  for (int i = 0; i < 20; ++i) {
    std::string name = fuzzer.String();
    // Made bad for sure: a character outside the plain-name alphabet, at the start or the end
    // (never inside a UTF-8 sequence: proto3 strings must stay valid UTF-8).
    static const std::string kBad = "/\\ \t:*?<>|\"'$`";
    name.insert(rng() % 2 == 0 ? 0 : name.size(), 1, kBad[rng() % kBad.size()]);
    bad_names.push_back(name);
  }
  std::vector<std::string> good_names = {"ok-1", "A.b_c", std::string(64, 'g'), "x"};
  for (int i = 0; i < 4; ++i) {
    std::string name(1 + rng() % 64, 'a');
    for (char& c : name) c = allowed[rng() % allowed.size()];
    if (name[0] == '.') name[0] = 'r';
    if (std::find(good_names.begin(), good_names.end(), name) == good_names.end())
      good_names.push_back(name);
  }
  int names_refused = 0;
  for (const std::string& name : bad_names) {
    Drain();
    v1::StartRecordingRequest request;
    request.set_name(name);
    v1::RecordingStatus status;
    const grpc::Status started = client_->StartRecording(request, &status);
    EXPECT_EQ(started.error_code(), grpc::StatusCode::INVALID_ARGUMENT)
        << "name '" << name << "': " << started.error_message();
    EXPECT_THAT(started.error_message(), HasSubstr("name"));
    if (started.ok()) client_->StopRecording(&status);
    names_refused += started.error_code() == grpc::StatusCode::INVALID_ARGUMENT ? 1 : 0;
  }
  for (const uint64_t max_bytes : {uint64_t{1}, uint64_t{1} << 19, (uint64_t{1} << 20) - 1}) {
    v1::StartRecordingRequest request;
    request.set_name("limit");
    request.set_max_bytes(max_bytes);
    v1::RecordingStatus status;
    const grpc::Status started = client_->StartRecording(request, &status);
    EXPECT_EQ(started.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << max_bytes;
    EXPECT_THAT(started.error_message(), HasSubstr("max_bytes"));
  }
  std::set<std::string> expected_recordings;
  for (size_t i = 0; i < good_names.size(); ++i) {
    v1::StartRecordingRequest request;
    request.set_name(good_names[i]);
    request.set_max_bytes(i % 2 == 0 ? uint64_t{1} << 20 : UINT64_MAX);
    v1::RecordingStatus status;
    const grpc::Status started = client_->StartRecording(request, &status);
    ASSERT_TRUE(started.ok()) << "name '" << good_names[i] << "': " << started.error_message();
    EXPECT_EQ(fs::path(status.dir()).lexically_normal(),
              (fs::path(data_dir_) / "recordings" / good_names[i]).lexically_normal());
    expected_recordings.insert(good_names[i]);
    const grpc::Status stopped = client_->StopRecording(&status);
    ASSERT_TRUE(stopped.ok()) << stopped.error_message();
    EXPECT_FALSE(status.active());
  }

  // Nothing outside DATA_DIR/recordings: the sandbox holds only the data directory, which holds
  // only the store's files and `recordings`, which holds only the good names.
  std::vector<std::string> sandbox_entries, data_entries, recording_entries;
  for (const auto& e : fs::directory_iterator(sandbox_))
    sandbox_entries.push_back(e.path().filename());
  for (const auto& e : fs::directory_iterator(data_dir_))
    data_entries.push_back(e.path().filename());
  for (const auto& e : fs::directory_iterator(data_dir_ + "/recordings")) {
    recording_entries.push_back(e.path().filename());
  }
  EXPECT_THAT(sandbox_entries, ::testing::UnorderedElementsAre("data"));
  EXPECT_THAT(data_entries,
              ::testing::UnorderedElementsAre("cal-000001.yaml", "cal-000001.report.yaml", "active",
                                              "recordings"));
  EXPECT_THAT(recording_entries, ::testing::UnorderedElementsAreArray(expected_recordings));
  EXPECT_FALSE(fs::exists("/abs"));

  std::string codes;
  for (const auto& [code, n] : calibration_codes) codes += " " + code + " x" + std::to_string(n);
  std::printf(
      "requests: StreamTracks %d streamed, %d refused; GetCalibration %zu ids:%s; "
      "StartRecording %d bad names refused, %zu good names recorded\n",
      streams_ok, streams_refused, ids.size(), codes.c_str(), names_refused,
      expected_recordings.size());
  ASSERT_NO_FATAL_FAILURE(ExpectServing("randomised requests"));
}

// A peer that opened an HTTP/2 connection and then went silent (a client that vanished without a
// FIN): with keepalive_time_s 1 and keepalive_timeout_s 1 the server pings it, gets no answer and
// closes the connection within a few seconds; with the defaults (30 s, 10 s) the same connection
// is still open after those seconds. Measured from the same kind of connection in one test.
TEST(FaultKeepalive, ASilentPeerIsClosedByTheConfiguredKeepalive) {
  const std::string preface("PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n", 24);
  const std::string empty_settings("\x00\x00\x00\x04\x00\x00\x00\x00\x00", 9);
  // Opens the connection, then reads (answering nothing) for at most `limit`: the seconds until
  // the server closed it, or nullopt when it was still open.
  const auto closed_after = [&](const std::string& address,
                                std::chrono::milliseconds limit) -> std::optional<double> {
    const int fd = testing::ConnectTcp(testing::PortOf(address), limit);
    if (fd < 0) return std::nullopt;
    const auto start = std::chrono::steady_clock::now();
    testing::SendAll(fd, preface + empty_settings);
    const bool closed = testing::ReadUntilClosed(fd);
    const double s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    ::close(fd);
    return closed ? std::optional<double>(s) : std::nullopt;
  };
  const std::string dir = testing::MakeTempDir("stevi-keepalive");
  const std::string config = dir + "/server.textproto";
  std::ofstream(config) << "keepalive_time_s: 1\nkeepalive_timeout_s: 1\n";
  testing::ServerProcess quick;
  ASSERT_NO_FATAL_FAILURE(quick.Start({"--fps", "5", "--config", config}));
  const std::optional<double> quick_s = closed_after(quick.address(), std::chrono::seconds(10));
  testing::ServerProcess defaults;
  ASSERT_NO_FATAL_FAILURE(defaults.Start({"--fps", "5"}));
  const std::optional<double> default_s = closed_after(defaults.address(), std::chrono::seconds(5));
  ASSERT_TRUE(quick_s.has_value()) << "a silent peer was still connected after 10 s";
  EXPECT_GE(*quick_s, 1.0) << "closed before any keepalive could have run";
  EXPECT_FALSE(default_s.has_value()) << "closed after " << *default_s << " s with the defaults";
  std::printf(
      "keepalive: a silent peer closed after %.2f s with 1 s / 1 s; still open after 5 s "
      "with the defaults\n",
      *quick_s);
}

// ---------------------------------------------------------------------------------------------
// A corrupt calibration store on disk.
// ---------------------------------------------------------------------------------------------

TEST(FaultStart, CorruptCalibrationStoreStillStartsSaysSoAndServes) {
  const std::string data_dir = testing::MakeTempDir("stevi-fault-store") + "/data";
  ASSERT_NO_FATAL_FAILURE(WriteGoodStore(data_dir));
  std::mt19937 rng(99);
  // Random bytes; a truncated YAML; YAML claiming absurd matrix sizes; a report without its
  // calibration; and an `active` file of random bytes.
  WriteFile(data_dir + "/cal-000002.yaml", RandomBytes(rng, 4096));
  WriteFile(data_dir + "/cal-000002.report.yaml", RandomBytes(rng, 512));
  WriteFile(data_dir + "/cal-000003.yaml",
            "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\nM1: !!opencv-matrix\n   rows: 3\n"
            "   cols: 3\n   dt: d\n   data: [ 700., 0., 320., 0.,");
  WriteFile(data_dir + "/cal-000004.yaml",
            "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\nM1: !!opencv-matrix\n"
            "   rows: 1000000000\n   cols: 1000000000\n   dt: d\n   data: [ 1. ]\n");
  WriteFile(data_dir + "/cal-000005.report.yaml", "created_unix_ms: 1\npassed: 1\n");
  WriteFile(data_dir + "/active", RandomBytes(rng, 300));

  testing::ServerProcess server;
  const Clock::time_point t0 = Clock::now();
  ASSERT_NO_FATAL_FAILURE(server.Start({"--fps", kFps, "--data-dir", data_dir}, false));
  const double start_s = testing::Seconds(Clock::now() - t0);
  // It says so at start, naming the files.
  const std::string said = server.process()->DrainStderr();
  EXPECT_THAT(said, ::testing::ContainsRegex("calibration.store"));
  EXPECT_THAT(said, HasSubstr("cal-000002.yaml"));
  EXPECT_THAT(said, HasSubstr("cal-000003.yaml"));
  EXPECT_THAT(said, HasSubstr("cal-000004.yaml"));
  EXPECT_THAT(said, HasSubstr("active"));

  // It serves, with the last good calibration.
  std::unique_ptr<client::Client> c = testing::MakeClient(server.address());
  v1::GetStatusResponse status;
  EXPECT_TRUE(testing::WaitForStatus(
      *c,
      [](const v1::GetStatusResponse& s) { return s.source_state() == v1::SOURCE_STATE_RUNNING; },
      30s, &status))
      << v1::SourceState_Name(status.source_state());
  EXPECT_EQ(status.calibration_id(), "cal-000001");
  v1::ListCalibrationsResponse list;
  ASSERT_TRUE(c->ListCalibrations(&list).ok());
  ASSERT_EQ(list.calibrations_size(), 1);
  EXPECT_EQ(list.calibrations(0).calibration_id(), "cal-000001");
  EXPECT_EQ(list.active_id(), "cal-000001");
  EXPECT_GE(list.store_problems_size(), 4);
  grpc::Status streamed;
  const std::vector<v1::TrackFrame> frames =
      testing::ReceiveFrames(server.address(), 5, 30s, &streamed);
  ASSERT_EQ(frames.size(), 5u) << streamed.error_message();
  for (const v1::TrackFrame& f : frames) EXPECT_EQ(f.calibration_id(), "cal-000001");
  // The corrupt calibration files are left as they were, for inspection.
  EXPECT_EQ(fs::file_size(data_dir + "/cal-000002.yaml"), 4096u);
  EXPECT_EQ(fs::file_size(data_dir + "/cal-000002.report.yaml"), 512u);
  std::printf("corrupt store: started in %.2f s; %d problems reported:\n", start_s,
              list.store_problems_size());
  for (const std::string& p : list.store_problems()) std::printf("  %.160s\n", p.c_str());
}

std::string ReadText(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

// The operator's choice survives a calibration that cannot be read at one start: `active` names
// cal-000002, whose file is damaged; the server falls back to cal-000001 (and says so) but must
// not forget the choice (CalibrationStore::Open: "the active file is left as it was until the next
// Activate()"), so that once the file is repaired the next start uses cal-000002 again.
TEST(FaultStart, ActiveChoiceSurvivesAnUnreadableCalibration) {
  const std::string data_dir = testing::MakeTempDir("stevi-fault-active") + "/data";
  ASSERT_NO_FATAL_FAILURE(WriteGoodStore(data_dir));  // cal-000001, active
  {
    Result<calibration::OpenedStore> opened = calibration::CalibrationStore::Open(data_dir);
    ASSERT_TRUE(opened.ok()) << opened.error().message;
    calibration::CalibrationReport report;
    report.image_size = cv::Size(640, 480);
    report.passed = true;
    Result<calibration::CalibrationId> id = opened->store->Add(
        geometry::IdealCalibration(cv::Size(640, 480), 700, 0.6, 321, 240), report);
    ASSERT_TRUE(id.ok()) << id.error().message;
    ASSERT_EQ(id->Name(), "cal-000002");
    ASSERT_TRUE(opened->store->Activate(*id).ok());
  }
  const std::string good_yaml = ReadText(data_dir + "/cal-000002.yaml");
  ASSERT_FALSE(good_yaml.empty());
  WriteFile(data_dir + "/cal-000002.yaml", good_yaml.substr(0, good_yaml.size() / 3));  // torn
  ASSERT_EQ(ReadText(data_dir + "/active"), "cal-000002\n");

  std::string first_calibration, first_said;
  {
    testing::ServerProcess server;
    ASSERT_NO_FATAL_FAILURE(server.Start({"--fps", kFps, "--data-dir", data_dir}, false));
    first_said = server.process()->DrainStderr();
    std::unique_ptr<client::Client> c = testing::MakeClient(server.address());
    v1::GetStatusResponse status;
    ASSERT_TRUE(c->GetStatus(&status).ok());
    first_calibration = status.calibration_id();
  }
  EXPECT_EQ(first_calibration, "cal-000001") << "the fallback is the last good calibration";
  EXPECT_THAT(first_said, HasSubstr("cal-000002"));
  EXPECT_EQ(ReadText(data_dir + "/active"), "cal-000002\n")
      << "the server replaced the operator's choice (cal-000002) by its fallback at start";

  // Repaired: the next start uses the operator's choice again.
  WriteFile(data_dir + "/cal-000002.yaml", good_yaml);
  testing::ServerProcess server;
  ASSERT_NO_FATAL_FAILURE(server.Start({"--fps", kFps, "--data-dir", data_dir}, false));
  std::unique_ptr<client::Client> c = testing::MakeClient(server.address());
  v1::GetStatusResponse status;
  ASSERT_TRUE(c->GetStatus(&status).ok());
  EXPECT_EQ(status.calibration_id(), "cal-000002")
      << "after the repair the server still uses its fallback: the active choice was lost";
  std::printf(
      "active choice: first start used %s; `active` then held \"%s\"; after the repair: %s\n",
      first_calibration.c_str(), ReadText(data_dir + "/active").c_str(),
      status.calibration_id().c_str());
}

// ---------------------------------------------------------------------------------------------
// A full disk while recording.
// ---------------------------------------------------------------------------------------------

// The server on a data directory that fills up: a 6 MiB tmpfs in a user + mount namespace of its
// own (unshare -rm), or, where that is not possible, RLIMIT_FSIZE (prlimit) with SIGXFSZ ignored.
// On exit the wrapper copies DATA_DIR/recordings to `out` (the tmpfs dies with the namespace).
struct FullDiskServer {
  std::unique_ptr<testing::Subprocess> process;
  std::string address;
  std::string recordings;  // where the recordings can be read once the server stopped
  std::string mode;
};

bool CanMountTmpfs(const std::string& dir) {
  const testing::RunResult r = testing::Run(
      {"/usr/bin/unshare", "-rm", "/bin/sh", "-c", "mount -t tmpfs -o size=1m probe \"$0\"", dir},
      20s);
  return r.exit_code == 0;
}

void StartFullDiskServer(FullDiskServer& s) {
  const std::string root = testing::MakeTempDir("stevi-fault-disk");
  const std::string mnt = root + "/mnt";
  const std::string out = root + "/out";
  fs::create_directories(mnt);
  fs::create_directories(out);
  const std::vector<std::string> server_args = {testing::BinaryPath("stevi-server"), "--listen",
                                                "127.0.0.1:0", "--fps", kFps};
  const std::string pdeath =
      fs::exists("/usr/bin/setpriv") ? "/usr/bin/setpriv --pdeathsig KILL -- " : "";
  std::vector<std::string> argv;
  if (fs::exists("/usr/bin/unshare") && CanMountTmpfs(mnt)) {
    s.mode = "6 MiB tmpfs (unshare -rm)";
    s.recordings = out + "/recordings";
    // The server runs as the shell's child so that the shell can copy the recordings out of the
    // tmpfs after it stopped; SIGTERM to the shell is passed on to the server.
    const std::string script =
        "mnt=$1; out=$2; shift 2\n"
        "mount -t tmpfs -o size=6m stevi-full \"$mnt\" || exit 97\n"
        "mkdir -p \"$mnt/data\" || exit 98\n" +
        pdeath +
        "\"$@\" --data-dir \"$mnt/data\" &\n"
        "pid=$!\n"
        "trap 'kill -TERM $pid 2>/dev/null' TERM INT\n"
        "while :; do wait $pid; rc=$?; kill -0 $pid 2>/dev/null || break; done\n"
        "echo \"wrapper: the server exited with $rc\" >&2\n"
        "cp -R \"$mnt/data/recordings\" \"$out/\" && echo 'wrapper: copied the recordings' >&2\n"
        "exit $rc\n";
    argv = {"/usr/bin/unshare", "-rm", "/bin/sh", "-c", script, "sh", mnt, out};
  } else {
    s.mode = "RLIMIT_FSIZE 6 MiB (prlimit)";
    s.recordings = mnt + "/data/recordings";
    argv = {"/bin/sh", "-c",
            "trap '' XFSZ; exec /usr/bin/prlimit --fsize=6291456 -- \"$@\" --data-dir \"$0/data\"",
            mnt};
  }
  argv.insert(argv.end(), server_args.begin(), server_args.end());
  s.process = std::make_unique<testing::Subprocess>(argv);
  const std::optional<std::string> line = s.process->WaitForStderrLine("serving", 60s);
  ASSERT_TRUE(line.has_value()) << "the server did not start (" << s.mode
                                << "): " << s.process->DrainStderr();
  std::smatch m;
  ASSERT_TRUE(std::regex_search(*line, m, std::regex("127\\.0\\.0\\.1:(\\d+)"))) << *line;
  s.address = "127.0.0.1:" + m[1].str();
}

TEST(FaultDisk, FullDiskStopsTheRecordingWhichStillReplays) {
  FullDiskServer server;
  ASSERT_NO_FATAL_FAILURE(StartFullDiskServer(server));
  std::unique_ptr<client::Client> c = testing::MakeClient(server.address);
  const testing::ServerState before = testing::ReadState(*c);

  v1::StartRecordingRequest request;
  request.set_name("full");  // default limit, 4 GiB: the disk fills long before
  v1::RecordingStatus started;
  const grpc::Status start = c->StartRecording(request, &started);
  ASSERT_TRUE(start.ok()) << start.error_message();
  ASSERT_TRUE(started.active());

  // It stops by itself (bounded: 6 MiB at ~0.5 MiB a frame and 15 fps is about a second).
  v1::GetStatusResponse status;
  const Clock::time_point t0 = Clock::now();
  ASSERT_TRUE(testing::WaitForStatus(
      *c, [](const v1::GetStatusResponse& s) { return !s.recording().active(); }, 60s, &status))
      << "still recording after 60 s on a 6 MiB disk: " << status.recording().ShortDebugString();
  const double stop_s = testing::Seconds(Clock::now() - t0);
  const v1::RecordingStatus rec = status.recording();
  EXPECT_FALSE(rec.stop_reason().empty()) << "the status does not say why the recording stopped";
  EXPECT_THAT(rec.stop_reason(), ::testing::Not(HasSubstr("request")));
  EXPECT_GT(rec.frames_written(), 0u);
  EXPECT_LT(rec.bytes_written(), uint64_t{6} << 20);

  // The server keeps streaming and nothing else is lost.
  grpc::Status streamed;
  const std::vector<v1::TrackFrame> frames =
      testing::ReceiveFrames(server.address, 10, 30s, &streamed);
  ASSERT_EQ(frames.size(), 10u) << streamed.error_message();
  for (size_t i = 1; i < frames.size(); ++i)
    EXPECT_EQ(frames[i].frame_id(), frames[i - 1].frame_id() + 1);
  ASSERT_TRUE(c->GetStatus(&status).ok());
  EXPECT_EQ(status.source_state(), v1::SOURCE_STATE_RUNNING);
  testing::ExpectSameState(before, testing::ReadState(*c), "a full disk");
  // Asking again on the full disk: a clean refusal or a recording that stops by itself, never a
  // crash.
  request.set_name("again");
  v1::RecordingStatus again;
  const grpc::Status second = c->StartRecording(request, &again);
  if (second.ok()) {
    EXPECT_TRUE(testing::WaitForStatus(
        *c, [](const v1::GetStatusResponse& s) { return !s.recording().active(); }, 60s, &status));
    EXPECT_FALSE(status.recording().stop_reason().empty());
  }
  grpc::Status streamed_again;
  ASSERT_EQ(testing::ReceiveFrames(server.address, 3, 30s, &streamed_again).size(), 3u)
      << streamed_again.error_message();

  // Stop the server (the wrapper copies the recordings out), then replay the partial recording.
  server.process->Signal(SIGTERM);
  const std::optional<int> code = server.process->Wait(60s);
  const std::string said = server.process->DrainStderr();
  EXPECT_EQ(code, std::optional<int>(0)) << said;
  const std::string dir = server.recordings + "/full";
  ASSERT_TRUE(fs::exists(dir + "/manifest.json")) << said;
  const testing::RunResult replay =
      testing::Run({testing::BinaryPath("stevi-process"), "--source", "replay", "--replay", dir},
                   testing::kCommandTimeout);
  ASSERT_EQ(replay.exit_code, 0) << replay.err;
  const size_t replayed = testing::ParseJsonLines<v1::TrackFrame>(replay.out).size();
  EXPECT_EQ(replayed, rec.frames_written());
  std::printf(
      "full disk (%s): recording stopped after %.2f s, %llu frames, %llu bytes: \"%s\"; "
      "second start: %s; replay: %zu frames\n",
      server.mode.c_str(), stop_s, static_cast<unsigned long long>(rec.frames_written()),
      static_cast<unsigned long long>(rec.bytes_written()), rec.stop_reason().c_str(),
      second.ok()
          ? ("ok, stopped: " + status.recording().stop_reason()).c_str()
          : (client::StatusCodeName(second.error_code()) + " " + second.error_message()).c_str(),
      replayed);
}

}  // namespace
}  // namespace stevi
