// stevi_client: a small C++ client for stevi-server (connect, stream tracks, control calls).
// Depends on the proto library only.
#pragma once

#include <chrono>
#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "stevi/v1/calibration_service.grpc.pb.h"
#include "stevi/v1/obstacle_service.grpc.pb.h"

namespace stevi::client {

// True when every byte is printable ASCII (0x20..0x7e): what a gRPC metadata value may hold, such
// as a bearer token. gRPC aborts the process on any other byte.
bool IsPrintableAscii(const std::string& text);

// How long one connection attempt (TCP, TLS, HTTP/2) may take before gRPC abandons it and tries
// again: long enough for a TLS handshake over a satellite link's round trip of a second or more.
inline constexpr int kMinConnectTimeoutMs = 10'000;
// The HTTP/2 receive window of StreamTracks (BDP probing off): how far a slow reader may fall
// behind before the server starts dropping frames for it. 16 KiB holds about 7 TrackFrames of ten
// tracks. Other clients of the API should do the same (see README, "Slow readers").
inline constexpr int kStreamLookaheadBytes = 16 << 10;
// The same for StreamPreview, on a connection of its own: a few JPEGs (a 640-pixel preview is
// 20-60 KiB), so that a reader who falls behind loses previews at the server, where they are
// counted (Preview.dropped_previews), rather than in this process's buffers.
inline constexpr int kPreviewLookaheadBytes = 256 << 10;

struct ClientOptions {
  std::string address = "127.0.0.1:50051";
  // Deadline of each unary call, and of connecting a stream.
  std::chrono::milliseconds timeout{5000};
  int max_message_bytes = 64 << 20;
  // Channel credentials: insecure (loopback) when null; grpc::SslCredentials(...) for TLS.
  std::shared_ptr<grpc::ChannelCredentials> credentials;
  // Sent as "authorization: Bearer TOKEN" with every call when not empty: the server's control
  // RPCs need it when it has an AuthConfig.token_file. Send it over TLS only.
  std::string bearer_token;
};

// What happens to a stream between frames, for consumers that log their gaps.
struct StreamEvent {
  enum class Kind {
    kLost,     // a stream that was delivering frames broke (status says why); reconnecting
    kResumed,  // the first frame after a loss arrived (gap: since the last frame before it)
  };
  Kind kind = Kind::kLost;
  grpc::Status status;               // kLost: why the stream ended
  std::chrono::milliseconds gap{0};  // kResumed: time without frames
  uint64_t reconnects = 0;           // streams opened again so far in this call
};

// Options of a streaming call (StreamTracks, StreamPreview): "frames" are its messages
// (TrackFrames, or Previews).
struct StreamOptions {
  // Stop after this many frames (0 = until cancelled or the server ends the stream).
  uint64_t max_frames = 0;
  // Reconnect when the stream breaks or cannot be opened, with a backoff from 0.1 s doubling to
  // max_backoff. Every end the caller did not ask for counts as a break: UNAVAILABLE, a server
  // that ends the stream (OK or CANCELLED from a graceful stop or a restart), DEADLINE_EXCEEDED,
  // ABORTED, INTERNAL, UNKNOWN, RESOURCE_EXHAUSTED (too many subscribers, for now). A refusal
  // that trying again cannot change ends the call: UNAUTHENTICATED, PERMISSION_DENIED,
  // INVALID_ARGUMENT, UNIMPLEMENTED, FAILED_PRECONDITION, NOT_FOUND, OUT_OF_RANGE.
  bool reconnect = false;
  // Give up after this many failed attempts in a row (0 = never give up).
  int max_reconnect_attempts = 10;
  // Once a frame has arrived, never give up: a server restart or an outage of any length is
  // survived, and max_reconnect_attempts bounds only the attempts before the first frame (so that
  // a wrong address still fails fast). What the streaming commands use.
  bool persist_once_streaming = false;
  std::chrono::milliseconds max_backoff{1000};
  // Called on the streaming thread when a stream that delivered frames breaks and when frames
  // resume; never for the attempts before the first frame.
  std::function<void(const StreamEvent&)> on_event;
  // StreamTracks' server-side filters: no TENTATIVE tracks; only tracks scoring at least
  // min_score (0..1).
  bool confirmed_only = false;
  double min_score = 0.0;
};

// True when a stream that ended with `status` (not cancelled by its caller) may succeed when
// opened again (see StreamOptions::reconnect).
bool IsTransientStreamEnd(const grpc::Status& status);

// A long-lived PublishVehicleState stream: an autopilot bridge's feed of vehicle states, with the
// client's credentials and no deadline. Write() from one thread; Cancel() from any.
class VehicleStatePublisher {
 public:
  // False when the stream broke (the server went away or refused the call): Finish() tells why,
  // and a new publisher goes on.
  bool Write(const v1::VehicleState& state);
  // Ends the stream and returns the server's status, and its counts in `response`.
  grpc::Status Finish(v1::PublishVehicleStateResponse* response);
  void Cancel() { context_.TryCancel(); }

 private:
  friend class Client;
  grpc::ClientContext context_;
  v1::PublishVehicleStateResponse response_;
  std::unique_ptr<grpc::ClientWriter<v1::VehicleState>> writer_;
  bool done_ = false;
};

// Thread-safe, except that one streaming call (StreamTracks() or StreamPreview()) runs at a time
// per Client.
class Client {
 public:
  explicit Client(ClientOptions options);

  grpc::Status GetStatus(v1::GetStatusResponse* response);
  grpc::Status GetPipelineConfig(v1::PipelineConfig* response);
  // Sends only the fields that are set; the server merges them and returns the active config.
  grpc::Status SetPipelineConfig(const v1::PipelineConfig& update, v1::PipelineConfig* active);
  // With `annotated`, the snapshot also carries the left image with the obstacles drawn on it.
  grpc::Status GetDisparitySnapshot(v1::DisparitySnapshot* response, bool annotated = false);

  // Calls on_frame for every frame until it returns false, max_frames arrived, Cancel() is called,
  // or the stream fails (and reconnecting, if asked, gives up). Returns OK in the first three
  // cases, else the last failure (a server that ended the stream is UNAVAILABLE "the server ended
  // the stream").
  grpc::Status StreamTracks(const std::function<bool(const v1::TrackFrame&)>& on_frame,
                            const StreamOptions& options = {});
  // JPEG previews of the processed frames (see StreamPreviewRequest), on a connection of its own,
  // with the same ending, reconnection and events as StreamTracks(); options.max_frames counts
  // previews. A bad request is INVALID_ARGUMENT naming the field (never retried).
  grpc::Status StreamPreview(const v1::StreamPreviewRequest& request,
                             const std::function<bool(const v1::Preview&)>& on_preview,
                             const StreamOptions& options = {});
  // Calibration (CalibrationService). Calibrate() streams `settings` then every pair; the
  // deadline is `calibrate_timeout` (calibrating 25 pairs takes seconds).
  grpc::Status Calibrate(const v1::CalibrationSettings& settings,
                         const std::vector<v1::ImagePair>& pairs, v1::CalibrationReport* report,
                         std::chrono::milliseconds calibrate_timeout = std::chrono::minutes(5));
  // Streams the server's capture progress to on_progress (the last message holds the report).
  grpc::Status CaptureCalibration(
      const v1::CaptureCalibrationRequest& request,
      const std::function<void(const v1::CaptureProgress&)>& on_progress,
      std::chrono::milliseconds capture_timeout = std::chrono::minutes(10));
  grpc::Status ListCalibrations(v1::ListCalibrationsResponse* response);
  // Streams vehicle states to the server (an autopilot's feed) and returns its counts.
  grpc::Status PublishVehicleStates(const std::vector<v1::VehicleState>& states,
                                    v1::PublishVehicleStateResponse* response);
  // Opens a PublishVehicleState stream to write states one by one as they come.
  std::unique_ptr<VehicleStatePublisher> OpenVehicleStatePublisher();
  // Recording on the server (DATA_DIR/recordings/NAME).
  grpc::Status StartRecording(const v1::StartRecordingRequest& request,
                              v1::RecordingStatus* status);
  grpc::Status StopRecording(v1::RecordingStatus* status);
  grpc::Status GetCalibration(const std::string& id, v1::CalibrationRecord* record);
  grpc::Status ActivateCalibration(const std::string& id, v1::CalibrationRecord* record);

  // Ends a running StreamTracks() or StreamPreview() from another thread, also while it waits to
  // reconnect.
  void Cancel();

  const ClientOptions& options() const { return options_; }

 private:
  // A deadline `timeout` from now and the credentials metadata.
  void Prepare(grpc::ClientContext& context, std::chrono::milliseconds timeout) const;
  // The unary deadline (options_.timeout) and the credentials metadata.
  void Prepare(grpc::ClientContext& context) const { Prepare(context, options_.timeout); }
  // The credentials metadata alone (streams set their own deadlines).
  void AddCredentials(grpc::ClientContext& context) const;
  // A unary call of `stub` with Prepare's deadline and credentials.
  template <class Stub, class Request, class Response>
  grpc::Status Unary(Stub& stub,
                     grpc::Status (Stub::*method)(grpc::ClientContext*, const Request&, Response*),
                     const Request& request, Response* response) const;

  ClientOptions options_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::ObstacleService::Stub> stub_;
  std::unique_ptr<v1::CalibrationService::Stub> calibration_stub_;
  std::shared_ptr<grpc::Channel> stream_channel_;  // StreamTracks only: a small receive window
  std::unique_ptr<v1::ObstacleService::Stub> stream_stub_;
  std::shared_ptr<grpc::Channel> preview_channel_;  // StreamPreview only
  std::unique_ptr<v1::ObstacleService::Stub> preview_stub_;
  // Opens one server stream of `Message` with `context` (the stub's call, on `channel`).
  template <typename Message>
  using OpenStream =
      std::function<std::unique_ptr<grpc::ClientReader<Message>>(grpc::ClientContext& context)>;
  // The body of every streaming call: attempts (StreamOnce) with reconnection, backoff, the
  // events and the end of the call (see StreamTracks()).
  template <typename Message>
  grpc::Status StreamWithReconnect(grpc::Channel& channel, const OpenStream<Message>& open,
                                   const std::function<bool(const Message&)>& on_message,
                                   const StreamOptions& options);
  // One attempt: opens the stream and reads it until it ends.
  struct Attempt {
    grpc::Status status;
    bool stop = false;        // the caller's on_frame, max_frames or Cancel() ended it
    bool got_frames = false;  // at least one frame arrived on this stream
  };
  template <typename Message>
  Attempt StreamOnce(grpc::Channel& channel, const OpenStream<Message>& open,
                     const std::function<bool(const Message&)>& on_message,
                     const StreamOptions& options, uint64_t& received);
  // Waits until `channel` is connected: false after options_.timeout or on Cancel().
  bool WaitForStreamChannel(grpc::Channel& channel);
  // Waits `delay` or until Cancel(); false when cancelled.
  bool WaitToReconnect(std::chrono::milliseconds delay);

  std::mutex stream_mu_;
  std::condition_variable stream_cv_;  // Cancel() wakes WaitToReconnect()
  grpc::ClientContext* stream_context_ = nullptr;
  bool cancelled_ = false;  // guarded by stream_mu_
};

// "UNAVAILABLE", "INVALID_ARGUMENT", ...
std::string StatusCodeName(grpc::StatusCode code);

}  // namespace stevi::client
