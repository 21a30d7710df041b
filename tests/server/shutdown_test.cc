// Graceful shutdown of the real stevi-server on SIGTERM: it exits 0 within 5 s, after (1) no
// longer accepting, (2) ending the streams with a final status, (3) stopping the source and
// (4) flushing the recording, in that order, each step logged. Also when the source is a replay
// waiting out a long recorded gap. And server reflection, which operators' tools (grpcurl,
// grpc_cli) use on the running server.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <csignal>
#include <regex>

#include <google/protobuf/unknown_field_set.h>
#include <grpcpp/generic/generic_stub.h>
#include <thread>

#include "drivers/recording/recording_reader.h"
#include "tests/server/load_helpers.h"
#include "tests/server/server_process.h"

namespace stevi {
namespace {

using namespace std::chrono_literals;
using ::testing::HasSubstr;

constexpr auto kGracefulBound = 5s;  // the bound on a SIGTERM

// A StreamTracks call on a thread of its own: frames counted, the final status kept.
class Watcher {
 public:
  explicit Watcher(const std::string& address) {
    thread_ = std::thread([this, address] {
      std::shared_ptr<grpc::Channel> channel = testing::PrivateChannel(address);
      std::unique_ptr<v1::ObstacleService::Stub> stub = v1::ObstacleService::NewStub(channel);
      grpc::ClientContext context;
      context.set_deadline(std::chrono::system_clock::now() + 120s);  // bounded
      std::unique_ptr<grpc::ClientReader<v1::TrackFrame>> reader =
          stub->StreamTracks(&context, v1::StreamTracksRequest());
      v1::TrackFrame frame;
      while (reader->Read(&frame)) count_.Add();
      count_.End(reader->Finish());
    });
  }
  ~Watcher() {
    if (thread_.joinable()) thread_.join();
  }

  bool WaitForFrames(uint64_t n, std::chrono::seconds timeout) {
    return count_.WaitFor(n, timeout) >= n;
  }
  // The final status once the stream ended (bounded).
  std::optional<grpc::Status> WaitForEnd(std::chrono::seconds timeout) {
    return count_.WaitForEnd(timeout);
  }

 private:
  testing::StreamCount count_;
  std::thread thread_;
};

// Offset of the first line of `log` holding every one of `needles`; npos when none does.
size_t LineWith(const std::string& log, const std::vector<std::string>& needles) {
  size_t start = 0;
  while (start < log.size()) {
    size_t end = log.find('\n', start);
    if (end == std::string::npos) end = log.size();
    const std::string line = log.substr(start, end - start);
    bool all = true;
    for (const std::string& n : needles) all = all && line.find(n) != std::string::npos;
    if (all) return start;
    start = end + 1;
  }
  return std::string::npos;
}

// SIGTERM, then the exit code and how long it took.
std::pair<std::optional<int>, double> Terminate(testing::ServerProcess& server) {
  const auto t0 = std::chrono::steady_clock::now();
  server.process()->Signal(SIGTERM);
  const std::optional<int> code = server.process()->Wait(30s);  // bounded; judged against 5 s
  return {code, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count()};
}

TEST(Shutdown, SigtermEndsStreamsStopsTheSourceFlushesTheRecordingInOrderWithinFiveSeconds) {
  const std::string dir = testing::MakeTempDir("stevi-shutdown") + "/flight";
  testing::ServerProcess server;
  ASSERT_NO_FATAL_FAILURE(server.Start({"--fps", "20", "--record", dir}));
  Watcher first(server.address());
  Watcher second(server.address());
  ASSERT_TRUE(first.WaitForFrames(10, 60s));
  ASSERT_TRUE(second.WaitForFrames(10, 60s));

  const auto [code, took_s] = Terminate(server);
  const std::string log = server.process()->DrainStderr();
  ASSERT_TRUE(code.has_value()) << "no exit within 30 s:\n" << log;
  EXPECT_EQ(*code, 0) << log;
  EXPECT_LT(took_s, std::chrono::duration<double>(kGracefulBound).count()) << log;

  // Both streams ended with the final status, not a broken connection.
  for (Watcher* w : {&first, &second}) {
    const std::optional<grpc::Status> status = w->WaitForEnd(10s);
    ASSERT_TRUE(status.has_value());
    EXPECT_EQ(status->error_code(), grpc::StatusCode::UNAVAILABLE) << status->error_message();
    EXPECT_THAT(status->error_message(), HasSubstr("shutting down"));
  }

  // The steps, in order, each logged once.
  const std::vector<std::vector<std::string>> steps = {
      {"event=shutting_down", "signal=SIGTERM"},
      {"event=shutdown", "step=stop_accepting"},
      {"event=shutdown", "step=streams_ended", "streams=2"},
      {"event=shutdown", "step=source_stopped"},
      {"event=shutdown", "step=recording_flushed"},
      {"event=stopped"}};
  size_t previous = 0;
  for (const std::vector<std::string>& step : steps) {
    const size_t at = LineWith(log, step);
    ASSERT_NE(at, std::string::npos) << "no line with " << step.back() << " in\n" << log;
    EXPECT_GE(at, previous) << step.back() << " came too early:\n" << log;
    previous = at;
  }

  // The recording was flushed whole: its manifest says why it stopped, and every frame the log
  // counted reads back, to a clean end.
  std::smatch m;
  ASSERT_TRUE(std::regex_search(log, m, std::regex("step=recording_flushed.*frames=(\\d+)")));
  const uint64_t flushed = std::stoull(m[1].str());
  Result<std::unique_ptr<drivers::RecordingReader>> reader = drivers::RecordingReader::Open(dir);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  EXPECT_EQ((*reader)->manifest().state(), v1::RECORDING_STATE_STOPPED);
  EXPECT_THAT((*reader)->manifest().stop_reason(), HasSubstr("server stopped"));
  EXPECT_EQ((*reader)->manifest().frames_written(), flushed);
  while ((*reader)->Next(/*decode_images=*/false)) {
  }
  EXPECT_EQ((*reader)->frames_read(), flushed);
  EXPECT_EQ((*reader)->end_note(), "");
  EXPECT_GE(flushed, 10u);
  std::printf("shutdown: exit %d after %.2f s; 2 streams ended UNAVAILABLE; %llu frames flushed\n",
              *code, took_s, static_cast<unsigned long long>(flushed));

  // A replay slowed down so that the next frame is seconds away: the stop does not wait for it.
  testing::ServerProcess replay;
  ASSERT_NO_FATAL_FAILURE(
      replay.Start({"--source", "replay", "--replay", dir, "--rate", "0.005"}));  // 50 ms -> 10 s
  Watcher watcher(replay.address());
  ASSERT_TRUE(watcher.WaitForFrames(1, 60s));  // the first frame comes at once
  const auto [replay_code, replay_s] = Terminate(replay);
  const std::string replay_log = replay.process()->DrainStderr();
  ASSERT_TRUE(replay_code.has_value()) << replay_log;
  EXPECT_EQ(*replay_code, 0) << replay_log;
  EXPECT_LT(replay_s, std::chrono::duration<double>(kGracefulBound).count()) << replay_log;
  std::printf("shutdown: a replay waiting 10 s for its next frame exited %d after %.2f s\n",
              *replay_code, replay_s);
}

// One exchange on the reflection service (grpc.reflection.v1alpha, from gRPC's own plugin),
// without its generated code: the request is ServerReflectionRequest{list_services: ""} (field
// 7, a string), and the answer's list_services_response (field 6) holds ServiceResponse
// messages (field 1) whose name is field 1. Bounded: every wait has a deadline.
std::vector<std::string> ListServicesByReflection(const std::string& address,
                                                  grpc::Status* status) {
  std::shared_ptr<grpc::Channel> channel = testing::PrivateChannel(address);
  grpc::GenericStub stub(channel);
  grpc::CompletionQueue cq;
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + 20s);
  std::unique_ptr<grpc::GenericClientAsyncReaderWriter> call = stub.PrepareCall(
      &context, "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo", &cq);
  const auto step = [&](void* tag) {
    void* got = nullptr;
    bool ok = false;
    const auto result = cq.AsyncNext(&got, &ok, std::chrono::system_clock::now() + 20s);
    return result == grpc::CompletionQueue::GOT_EVENT && got == tag && ok;
  };
  std::vector<std::string> names;
  int tags[5];
  call->StartCall(&tags[0]);
  if (step(&tags[0])) {
    const std::string request("\x3a\x00", 2);  // field 7, length 0
    grpc::Slice slice(request);
    grpc::ByteBuffer buffer(&slice, 1);
    call->Write(buffer, &tags[1]);
    if (step(&tags[1])) {
      call->WritesDone(&tags[2]);
      step(&tags[2]);
      grpc::ByteBuffer reply;
      call->Read(&reply, &tags[3]);
      std::vector<grpc::Slice> slices;
      if (step(&tags[3]) && reply.Dump(&slices).ok()) {
        std::string bytes;
        for (const grpc::Slice& s : slices)
          bytes.append(reinterpret_cast<const char*>(s.begin()), s.size());
        google::protobuf::UnknownFieldSet response, list;
        if (response.ParseFromString(bytes)) {
          for (int i = 0; i < response.field_count(); ++i) {
            const google::protobuf::UnknownField& f = response.field(i);
            if (f.number() != 6 ||
                f.type() != google::protobuf::UnknownField::TYPE_LENGTH_DELIMITED)
              continue;
            if (!list.ParseFromString(f.length_delimited())) continue;
            for (int j = 0; j < list.field_count(); ++j) {
              google::protobuf::UnknownFieldSet service;
              if (list.field(j).number() != 1 ||
                  list.field(j).type() != google::protobuf::UnknownField::TYPE_LENGTH_DELIMITED ||
                  !service.ParseFromString(list.field(j).length_delimited())) {
                continue;
              }
              for (int k = 0; k < service.field_count(); ++k) {
                if (service.field(k).number() == 1 &&
                    service.field(k).type() ==
                        google::protobuf::UnknownField::TYPE_LENGTH_DELIMITED) {
                  names.push_back(service.field(k).length_delimited());
                }
              }
            }
          }
        }
      }
    }
  }
  context.TryCancel();
  call->Finish(status, &tags[4]);
  step(&tags[4]);
  cq.Shutdown();
  void* ignored = nullptr;
  bool ok = false;
  while (cq.Next(&ignored, &ok)) {
  }
  return names;
}

TEST(Reflection, TheRunningServerListsItsServices) {
  testing::ServerProcess server;
  ASSERT_NO_FATAL_FAILURE(server.Start({"--fps", "10"}));
  grpc::Status status;
  const std::vector<std::string> names = ListServicesByReflection(server.address(), &status);
  EXPECT_THAT(names,
              ::testing::IsSupersetOf({"stevi.v1.ObstacleService", "stevi.v1.CalibrationService",
                                       "grpc.health.v1.Health"}))
      << status.error_message();
  std::string joined;
  for (const std::string& n : names) joined += " " + n;
  std::printf("reflection:%s\n", joined.c_str());
}

}  // namespace
}  // namespace stevi
