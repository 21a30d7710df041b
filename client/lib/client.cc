#include "client/lib/client.h"

#include <algorithm>
#include <optional>

namespace stevi::client {

std::string StatusCodeName(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::OK: return "OK";
    case grpc::StatusCode::CANCELLED: return "CANCELLED";
    case grpc::StatusCode::UNKNOWN: return "UNKNOWN";
    case grpc::StatusCode::INVALID_ARGUMENT: return "INVALID_ARGUMENT";
    case grpc::StatusCode::DEADLINE_EXCEEDED: return "DEADLINE_EXCEEDED";
    case grpc::StatusCode::NOT_FOUND: return "NOT_FOUND";
    case grpc::StatusCode::ALREADY_EXISTS: return "ALREADY_EXISTS";
    case grpc::StatusCode::PERMISSION_DENIED: return "PERMISSION_DENIED";
    case grpc::StatusCode::RESOURCE_EXHAUSTED: return "RESOURCE_EXHAUSTED";
    case grpc::StatusCode::FAILED_PRECONDITION: return "FAILED_PRECONDITION";
    case grpc::StatusCode::ABORTED: return "ABORTED";
    case grpc::StatusCode::OUT_OF_RANGE: return "OUT_OF_RANGE";
    case grpc::StatusCode::UNIMPLEMENTED: return "UNIMPLEMENTED";
    case grpc::StatusCode::INTERNAL: return "INTERNAL";
    case grpc::StatusCode::UNAVAILABLE: return "UNAVAILABLE";
    case grpc::StatusCode::DATA_LOSS: return "DATA_LOSS";
    case grpc::StatusCode::UNAUTHENTICATED: return "UNAUTHENTICATED";
    default: return "CODE_" + std::to_string(static_cast<int>(code));
  }
}

Client::Client(ClientOptions options) : options_(std::move(options)) {
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(options_.max_message_bytes);
  args.SetMaxSendMessageSize(options_.max_message_bytes);
  const std::shared_ptr<grpc::ChannelCredentials> credentials =
      options_.credentials ? options_.credentials : grpc::InsecureChannelCredentials();
  // After a server restart every call works again within a second: gRPC's own reconnection
  // backoff (1 s growing to 120 s by default) would otherwise fail calls for minutes, or hold a
  // stream's consumer silent as long.
  args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, 100);
  args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, 1000);
  // Despite its name, gRPC's "minimum reconnect backoff" is the least time a connection attempt
  // (TCP, TLS, HTTP/2) is given before it is abandoned. At 100 ms a TLS connection over a link
  // with a long round trip (satellite, congested LTE) was never made. A refused connection (the
  // server restarting) still fails at once and is retried within the backoff above.
  args.SetInt(GRPC_ARG_MIN_RECONNECT_BACKOFF_MS, kMinConnectTimeoutMs);
  channel_ = grpc::CreateCustomChannel(options_.address, credentials, args);
  stub_ = v1::ObstacleService::NewStub(channel_);
  calibration_stub_ = v1::CalibrationService::NewStub(channel_);
  // StreamTracks has a connection of its own with a small, fixed receive window. A reader that
  // falls behind then falls behind at the server, which drops frames for it (latest wins) and
  // says so in TrackFrame.dropped_frames. With gRPC's default BDP probing the window grows on a
  // fast link and the frames queue up in this process instead, ever older and never reported.
  // The unary calls keep the default window: a snapshot download over a radio link needs it.
  args.SetInt(GRPC_ARG_HTTP2_BDP_PROBE, 0);
  args.SetInt(GRPC_ARG_HTTP2_STREAM_LOOKAHEAD_BYTES, kStreamLookaheadBytes);
  stream_channel_ = grpc::CreateCustomChannel(options_.address, credentials, args);
  stream_stub_ = v1::ObstacleService::NewStub(stream_channel_);
  // StreamPreview: the same on a connection of its own, with a window of a few JPEGs (a preview
  // stream does not hold back the tracks, nor the tracks' window the previews). Channels connect
  // on first use: none is opened without a StreamPreview() call.
  args.SetInt(GRPC_ARG_HTTP2_STREAM_LOOKAHEAD_BYTES, kPreviewLookaheadBytes);
  preview_channel_ = grpc::CreateCustomChannel(options_.address, credentials, args);
  preview_stub_ = v1::ObstacleService::NewStub(preview_channel_);
}

grpc::Status Client::Calibrate(const v1::CalibrationSettings& settings,
                               const std::vector<v1::ImagePair>& pairs,
                               v1::CalibrationReport* report,
                               std::chrono::milliseconds calibrate_timeout) {
  grpc::ClientContext context;
  Prepare(context, calibrate_timeout);
  std::unique_ptr<grpc::ClientWriter<v1::CalibrationUpload>> writer =
      calibration_stub_->Calibrate(&context, report);
  v1::CalibrationUpload upload;
  *upload.mutable_settings() = settings;
  bool ok = writer->Write(upload);
  for (size_t i = 0; ok && i < pairs.size(); ++i) {
    *upload.mutable_pair() = pairs[i];
    ok = writer->Write(upload);
  }
  // A failed write means the server ended the call early; Finish() tells why.
  writer->WritesDone();
  return writer->Finish();
}

grpc::Status Client::CaptureCalibration(
    const v1::CaptureCalibrationRequest& request,
    const std::function<void(const v1::CaptureProgress&)>& on_progress,
    std::chrono::milliseconds capture_timeout) {
  grpc::ClientContext context;
  Prepare(context, capture_timeout);
  std::unique_ptr<grpc::ClientReader<v1::CaptureProgress>> reader =
      calibration_stub_->CaptureCalibration(&context, request);
  v1::CaptureProgress progress;
  while (reader->Read(&progress)) on_progress(progress);
  return reader->Finish();
}

grpc::Status Client::PublishVehicleStates(const std::vector<v1::VehicleState>& states,
                                          v1::PublishVehicleStateResponse* response) {
  grpc::ClientContext context;
  Prepare(context);
  std::unique_ptr<grpc::ClientWriter<v1::VehicleState>> writer =
      stub_->PublishVehicleState(&context, response);
  for (const v1::VehicleState& state : states) {
    if (!writer->Write(state)) break;
  }
  writer->WritesDone();
  return writer->Finish();
}

std::unique_ptr<VehicleStatePublisher> Client::OpenVehicleStatePublisher() {
  auto publisher = std::make_unique<VehicleStatePublisher>();
  AddCredentials(publisher->context_);
  publisher->writer_ = stub_->PublishVehicleState(&publisher->context_, &publisher->response_);
  return publisher;
}

bool VehicleStatePublisher::Write(const v1::VehicleState& state) {
  return !done_ && writer_->Write(state);
}

grpc::Status VehicleStatePublisher::Finish(v1::PublishVehicleStateResponse* response) {
  if (!done_) {
    writer_->WritesDone();
    done_ = true;
  }
  grpc::Status status = writer_->Finish();
  if (response != nullptr) *response = response_;
  return status;
}

template <class Stub, class Request, class Response>
grpc::Status Client::Unary(Stub& stub,
                           grpc::Status (Stub::*method)(grpc::ClientContext*, const Request&,
                                                        Response*),
                           const Request& request, Response* response) const {
  grpc::ClientContext context;
  Prepare(context);
  return (stub.*method)(&context, request, response);
}

grpc::Status Client::ListCalibrations(v1::ListCalibrationsResponse* response) {
  return Unary(*calibration_stub_, &v1::CalibrationService::Stub::ListCalibrations,
               v1::ListCalibrationsRequest(), response);
}

grpc::Status Client::GetCalibration(const std::string& id, v1::CalibrationRecord* record) {
  v1::GetCalibrationRequest request;
  request.set_calibration_id(id);
  return Unary(*calibration_stub_, &v1::CalibrationService::Stub::GetCalibration, request, record);
}

grpc::Status Client::ActivateCalibration(const std::string& id, v1::CalibrationRecord* record) {
  v1::ActivateCalibrationRequest request;
  request.set_calibration_id(id);
  return Unary(*calibration_stub_, &v1::CalibrationService::Stub::ActivateCalibration, request,
               record);
}

bool IsPrintableAscii(const std::string& text) {
  return std::all_of(text.begin(), text.end(), [](char c) { return c >= 0x20 && c <= 0x7e; });
}

void Client::AddCredentials(grpc::ClientContext& context) const {
  // gRPC aborts the process on a metadata value with any other byte: such a token is not sent
  // (the server then answers UNAUTHENTICATED). The CLI and the station refuse it before.
  if (!options_.bearer_token.empty() && IsPrintableAscii(options_.bearer_token)) {
    context.AddMetadata("authorization", "Bearer " + options_.bearer_token);
  }
}

void Client::Prepare(grpc::ClientContext& context, std::chrono::milliseconds timeout) const {
  context.set_deadline(std::chrono::system_clock::now() + timeout);
  AddCredentials(context);
}

grpc::Status Client::GetStatus(v1::GetStatusResponse* response) {
  return Unary(*stub_, &v1::ObstacleService::Stub::GetStatus, v1::GetStatusRequest(), response);
}

grpc::Status Client::StartRecording(const v1::StartRecordingRequest& request,
                                    v1::RecordingStatus* status) {
  return Unary(*stub_, &v1::ObstacleService::Stub::StartRecording, request, status);
}

grpc::Status Client::StopRecording(v1::RecordingStatus* status) {
  return Unary(*stub_, &v1::ObstacleService::Stub::StopRecording, v1::StopRecordingRequest(),
               status);
}

grpc::Status Client::GetPipelineConfig(v1::PipelineConfig* response) {
  return Unary(*stub_, &v1::ObstacleService::Stub::GetPipelineConfig,
               v1::GetPipelineConfigRequest(), response);
}

grpc::Status Client::SetPipelineConfig(const v1::PipelineConfig& update,
                                       v1::PipelineConfig* active) {
  v1::SetPipelineConfigRequest request;
  *request.mutable_config() = update;
  return Unary(*stub_, &v1::ObstacleService::Stub::SetPipelineConfig, request, active);
}

grpc::Status Client::GetDisparitySnapshot(v1::DisparitySnapshot* response, bool annotated) {
  v1::GetDisparitySnapshotRequest request;
  request.set_annotated(annotated);
  return Unary(*stub_, &v1::ObstacleService::Stub::GetDisparitySnapshot, request, response);
}

bool IsTransientStreamEnd(const grpc::Status& status) {
  switch (status.error_code()) {
    case grpc::StatusCode::OK:         // the server ended the stream
    case grpc::StatusCode::CANCELLED:  // by the server: a graceful stop, a restart
    case grpc::StatusCode::UNAVAILABLE:
    case grpc::StatusCode::DEADLINE_EXCEEDED:
    case grpc::StatusCode::ABORTED:
    case grpc::StatusCode::INTERNAL:
    case grpc::StatusCode::UNKNOWN:
    case grpc::StatusCode::RESOURCE_EXHAUSTED:
    case grpc::StatusCode::DATA_LOSS: return true;
    default: return false;
  }
}

template <typename Message>
Client::Attempt Client::StreamOnce(grpc::Channel& channel, const OpenStream<Message>& open,
                                   const std::function<bool(const Message&)>& on_message,
                                   const StreamOptions& options, uint64_t& received) {
  Attempt attempt;
  grpc::ClientContext context;
  AddCredentials(context);
  {
    std::lock_guard lock(stream_mu_);
    if (cancelled_) {
      attempt.stop = true;
      return attempt;
    }
    stream_context_ = &context;
  }
  // Fail fast when the server cannot be reached within the timeout.
  if (!WaitForStreamChannel(channel)) {
    attempt.status = grpc::Status(grpc::StatusCode::UNAVAILABLE,
                                  "cannot connect to " + options_.address + " within " +
                                      std::to_string(options_.timeout.count()) + " ms");
  } else {
    std::unique_ptr<grpc::ClientReader<Message>> reader = open(context);
    Message message;
    while (reader->Read(&message)) {
      attempt.got_frames = true;
      ++received;
      if (!on_message(message) || (options.max_frames > 0 && received >= options.max_frames)) {
        attempt.stop = true;
        context.TryCancel();
        break;
      }
    }
    attempt.status = reader->Finish();
    if (attempt.status.ok()) {
      attempt.status = grpc::Status(grpc::StatusCode::UNAVAILABLE, "the server ended the stream");
    }
  }
  std::lock_guard lock(stream_mu_);
  stream_context_ = nullptr;
  if (cancelled_) attempt.stop = true;
  return attempt;
}

bool Client::WaitForStreamChannel(grpc::Channel& channel) {
  // In slices, so that Cancel() is heard while the server is away.
  const auto deadline = std::chrono::system_clock::now() + options_.timeout;
  while (true) {
    const auto slice =
        std::min(deadline, std::chrono::system_clock::now() + std::chrono::milliseconds(100));
    if (channel.WaitForConnected(slice)) return true;
    std::lock_guard lock(stream_mu_);
    if (cancelled_ || std::chrono::system_clock::now() >= deadline) return false;
  }
}

bool Client::WaitToReconnect(std::chrono::milliseconds delay) {
  std::unique_lock lock(stream_mu_);
  return !stream_cv_.wait_for(lock, delay, [this] { return cancelled_; });
}

template <typename Message>
grpc::Status Client::StreamWithReconnect(grpc::Channel& channel, const OpenStream<Message>& open,
                                         const std::function<bool(const Message&)>& on_message,
                                         const StreamOptions& options) {
  {
    std::lock_guard lock(stream_mu_);
    cancelled_ = false;
  }
  uint64_t received = 0;
  int failures = 0;
  bool streaming = false;  // frames arrived since the call began
  uint64_t reconnects = 0;
  std::optional<std::chrono::steady_clock::time_point> lost_since;  // the last frame before a loss
  constexpr auto kFirstBackoff = std::chrono::milliseconds(100);
  auto backoff = kFirstBackoff;
  // Frames after a loss: the resume is reported before the first of them is handed on.
  const std::function<bool(const Message&)> on_message_after_loss = [&](const Message& message) {
    if (lost_since) {
      if (options.on_event) {
        StreamEvent event;
        event.kind = StreamEvent::Kind::kResumed;
        event.gap = std::chrono::duration_cast<std::chrono::milliseconds>(
            std::chrono::steady_clock::now() - *lost_since);
        event.reconnects = reconnects;
        options.on_event(event);
      }
      lost_since.reset();
    }
    return on_message(message);
  };
  while (true) {
    const Attempt attempt = StreamOnce(channel, open, on_message_after_loss, options, received);
    if (attempt.stop) return grpc::Status::OK;
    if (attempt.got_frames) {
      streaming = true;
      failures = 0;
      backoff = kFirstBackoff;
      lost_since = std::chrono::steady_clock::now();
      if (options.on_event && options.reconnect && IsTransientStreamEnd(attempt.status)) {
        StreamEvent event;
        event.kind = StreamEvent::Kind::kLost;
        event.status = attempt.status;
        event.reconnects = reconnects;
        options.on_event(event);
      }
    }
    if (!options.reconnect || !IsTransientStreamEnd(attempt.status)) return attempt.status;
    ++failures;
    const bool bounded =
        options.max_reconnect_attempts > 0 && !(streaming && options.persist_once_streaming);
    if (bounded && failures >= options.max_reconnect_attempts) return attempt.status;
    if (!WaitToReconnect(backoff)) return grpc::Status::OK;
    backoff = std::min(backoff * 2, options.max_backoff);
    ++reconnects;
  }
}

grpc::Status Client::StreamTracks(const std::function<bool(const v1::TrackFrame&)>& on_frame,
                                  const StreamOptions& options) {
  v1::StreamTracksRequest request;
  request.set_confirmed_only(options.confirmed_only);
  request.set_min_score(options.min_score);
  return StreamWithReconnect<v1::TrackFrame>(
      *stream_channel_,
      [&](grpc::ClientContext& context) { return stream_stub_->StreamTracks(&context, request); },
      on_frame, options);
}

grpc::Status Client::StreamPreview(const v1::StreamPreviewRequest& request,
                                   const std::function<bool(const v1::Preview&)>& on_preview,
                                   const StreamOptions& options) {
  return StreamWithReconnect<v1::Preview>(
      *preview_channel_,
      [&](grpc::ClientContext& context) { return preview_stub_->StreamPreview(&context, request); },
      on_preview, options);
}

void Client::Cancel() {
  std::lock_guard lock(stream_mu_);
  cancelled_ = true;
  if (stream_context_ != nullptr) stream_context_->TryCancel();
  stream_cv_.notify_all();
}

}  // namespace stevi::client
