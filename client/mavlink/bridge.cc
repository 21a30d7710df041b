#include "client/mavlink/bridge.h"

#include <ctime>
#include <future>
#include <iomanip>
#include <initializer_list>
#include <iostream>
#include <sstream>
#include <thread>

#include "client/lib/thread_name.h"

namespace stevi::client::mavlink {
namespace {

using Clock = Bridge::Clock;
using std::chrono::milliseconds;

// One logfmt line on stderr: "ts=... level=info event=EVENT key=value ...".
void Log(const char* level, const std::string& event,
         std::initializer_list<std::pair<std::string, std::string>> fields) {
  const auto now = std::chrono::system_clock::now();
  const std::time_t seconds = std::chrono::system_clock::to_time_t(now);
  const auto ms = std::chrono::duration_cast<milliseconds>(now.time_since_epoch()).count() % 1000;
  std::tm utc{};
  gmtime_r(&seconds, &utc);
  char ts[32];
  std::strftime(ts, sizeof ts, "%Y-%m-%dT%H:%M:%S", &utc);
  std::ostringstream line;
  line << "ts=" << ts << '.' << std::setw(3) << std::setfill('0') << ms << "Z level=" << level
       << " event=" << event;
  for (const auto& [key, value] : fields) {
    const bool quote = value.empty() || value.find_first_of(" \"=") != std::string::npos;
    line << ' ' << key << '=';
    if (!quote) {
      line << value;
      continue;
    }
    line << '"';
    for (const char c : value) {
      if (c == '"' || c == '\\') line << '\\';
      line << (c == '\n' ? ' ' : c);
    }
    line << '"';
  }
  std::cerr << line.str() << "\n" << std::flush;
}

std::string Str(uint64_t n) { return std::to_string(n); }

int64_t UnixNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// The messages the bridge asks the autopilot for, and how often (microseconds).
struct WantedMessage {
  uint32_t id;
  int32_t interval_us;
};
constexpr WantedMessage kWanted[] = {
    {GlobalPositionInt::kId, 50'000},  // 20 Hz
    {Attitude::kId, 50'000},           // 20 Hz
    {GpsRawInt::kId, 200'000},         // 5 Hz: the ellipsoid height and accuracies
    {SystemTime::kId, 1'000'000},      // 1 Hz: Unix time
};

}  // namespace

bool Bridge::OpenLinkNow() {
  std::string error;
  std::unique_ptr<Link> link = OpenLink(args_.link, error);
  if (!link) {
    Log("error", "link_error", {{"link", args_.link.text}, {"error", error}});
    return false;
  }
  Log("info", "link_open", {{"link", link->Describe()}});
  std::lock_guard lock(link_mu_);
  link_ = std::move(link);
  return true;
}

template <class T>
void Bridge::Send(const T& message) {
  const std::shared_ptr<Link> link = CurrentLink();
  if (!link || !link->HasPeer()) return;  // udpin: nobody spoke yet
  uint8_t system_id = 1;
  {
    std::lock_guard lock(mu_);
    if (args_.system_id) {
      system_id = static_cast<uint8_t>(*args_.system_id);
    } else if (autopilot_) {
      system_id = autopilot_->first;
    }
  }
  std::lock_guard lock(send_mu_);
  const std::vector<uint8_t> bytes =
      Encode(message, sequence_++, system_id, static_cast<uint8_t>(args_.component_id));
  if (std::string error = link->Send(bytes); !error.empty()) {
    ++send_errors_;
    if (error != last_send_error_) Log("warn", "send_failed", {{"error", error}});
    last_send_error_ = error;
  }
}

void Bridge::OnFrame(const v1::TrackFrame& frame) {
  std::string why;
  std::optional<ObstacleDistance> obstacles = ObstacleDistanceOf(frame, why);
  std::lock_guard lock(mu_);
  ++frames_in_;
  frame_arrived_ = Clock::now();
  geo_status_ = frame.geo_status();
  geo_message_ = frame.geo_message();
  if (!obstacles && why != no_obstacles_why_) Log("warn", "no_obstacle_distance", {{"why", why}});
  no_obstacles_why_ = why;
  obstacles_ = std::move(obstacles);
  if (args_.adsb) {
    adsb_.set_geoid_undulation_m(joiner_.geoid_undulation_m());
    adsb_batch_ = adsb_.Of(frame);
    adsb_pending_ = true;
  }
}

void Bridge::StreamLoop() {
  StreamOptions options;
  options.reconnect = true;
  options.persist_once_streaming = true;
  options.max_reconnect_attempts = 0;  // for ever: the bridge outlives any server restart
  options.on_event = [this](const StreamEvent& e) {
    if (e.kind == StreamEvent::Kind::kLost) {
      {
        std::lock_guard lock(mu_);
        ++stream_gaps_;
      }
      Log("warn", "stream_lost",
          {{"code", StatusCodeName(e.status.error_code())}, {"error", e.status.error_message()}});
    } else {
      Log("info", "stream_back", {{"gap_ms", Str(static_cast<uint64_t>(e.gap.count()))}});
    }
  };
  const grpc::Status status = client_.StreamTracks(
      [this](const v1::TrackFrame& frame) {
        OnFrame(frame);
        return !stopping_;
      },
      options);
  if (!status.ok() && !stopping_) {
    Log("error", "stream_failed",
        {{"code", StatusCodeName(status.error_code())}, {"error", status.error_message()}});
  }
}

void Bridge::LinkLoop() {
  Parser parser;
  std::vector<uint8_t> buffer(kLinkBufferBytes);
  while (!stopping_) {
    std::shared_ptr<Link> link = CurrentLink();
    if (!link) {
      if (!OpenLinkNow()) {
        if (!Wait(milliseconds(1000))) return;
        std::lock_guard lock(mu_);
        ++link_reopens_;
      }
      continue;
    }
    std::string error;
    const int n = link->Receive(buffer, milliseconds(200), error);
    if (n < 0) {
      Log("error", "link_lost", {{"link", link->Describe()}, {"error", error}});
      std::lock_guard lock(link_mu_);
      link_.reset();
      continue;
    }
    parser.Feed(std::span<const uint8_t>(buffer.data(), static_cast<size_t>(n)),
                [this](const Frame& frame) { OnMessage(frame); });
    std::lock_guard lock(mu_);
    parser_stats_ = parser.stats();
  }
}

void Bridge::OnMessage(const Frame& frame) {
  const int64_t host_unix_ns = UnixNowNs();
  std::lock_guard lock(mu_);
  ++messages_in_;
  if (const std::optional<Heartbeat> hb = Decode<Heartbeat>(frame)) {
    if (!IsAutopilotHeartbeat(*hb)) return;
    if (autopilot_ && autopilot_->first != frame.system_id) return;  // the first one heard
    if (!autopilot_ || autopilot_silent_) {
      Log("info", "autopilot_seen",
          {{"system_id", Str(frame.system_id)},
           {"component_id", Str(frame.component_id)},
           {"type", Str(hb->type)},
           {"autopilot", Str(hb->autopilot)}});
      last_request_ = {};  // ask for the streams at once
    }
    autopilot_ = std::make_pair(frame.system_id, frame.component_id);
    autopilot_heard_ = Clock::now();
    autopilot_silent_ = false;
    return;
  }
  if (!autopilot_ || frame.system_id != autopilot_->first) return;
  if (const std::optional<CommandAck> ack = Decode<CommandAck>(frame)) {
    if (ack->command == kMavCmdSetMessageInterval && ack->result != kMavResultAccepted) {
      Log("warn", "message_interval_refused", {{"result", Str(ack->result)}});
    }
    return;
  }
  last_received_[frame.message_id] = Clock::now();
  std::optional<v1::VehicleState> state = joiner_.OnMessage(frame, host_unix_ns);
  if (!state || !args_.publish_poses) return;
  ++states_made_;
  if (states_.size() >= 64) {
    states_.pop_front();  // the publisher is behind (the server is away): keep the newest
    ++states_dropped_;
  }
  states_.push_back(std::move(*state));
  cv_.notify_all();
}

void Bridge::PublishLoop() {
  while (!stopping_) {
    std::unique_ptr<VehicleStatePublisher> publisher = client_.OpenVehicleStatePublisher();
    bool broken = false;
    while (!broken) {
      std::optional<v1::VehicleState> state;
      {
        std::unique_lock lock(mu_);
        cv_.wait(lock, [this] { return stop_ || !states_.empty(); });
        if (stop_) break;
        state = std::move(states_.front());
        states_.pop_front();
      }
      broken = !publisher->Write(*state);
      std::lock_guard lock(mu_);
      if (broken) continue;
      ++states_published_;
      if (!publishing_) Log("info", "publishing", {});
      publishing_ = true;
    }
    if (stopping_) publisher->Cancel();
    v1::PublishVehicleStateResponse response;
    const grpc::Status status = publisher->Finish(&response);
    if (stopping_) return;
    bool was_publishing = false;
    {
      std::lock_guard lock(mu_);
      std::swap(was_publishing, publishing_);
    }
    if (was_publishing) {  // once per outage, not at every retry
      Log("warn", "publish_lost",
          {{"code", StatusCodeName(status.error_code())},
           {"error", status.error_message()},
           {"accepted", Str(response.accepted())},
           {"refused", Str(response.refused())},
           {"last_refusal", response.last_error()}});
    }
    if (!Wait(milliseconds(1000))) return;
  }
}

void Bridge::SendObstacles(Clock::time_point now) {
  // Nothing older than this goes out (the frame's arrival here; the server's latency is tens of
  // milliseconds on top): a stopped stream stops the obstacles within it.
  constexpr milliseconds kMaxAge(400);
  std::optional<ObstacleDistance> obstacles;
  std::vector<AdsbVehicle> adsb;
  {
    std::lock_guard lock(mu_);
    const bool fresh = obstacles_ && now - frame_arrived_ <= kMaxAge;
    if (fresh != obstacles_flowing_) {
      const auto age = std::chrono::duration_cast<milliseconds>(now - frame_arrived_).count();
      if (fresh) {
        Log("info", "obstacles_flowing", {});
      } else {
        Log("warn", "obstacles_stopped",
            {{"why", frames_in_ == 0 || no_obstacles_why_.empty()
                         ? "no frame for " + std::to_string(age) + " ms"
                         : no_obstacles_why_}});
      }
      obstacles_flowing_ = fresh;
    }
    if (!fresh) return;
    obstacles = obstacles_;
    if (adsb_pending_) {
      adsb = adsb_batch_;
      adsb_pending_ = false;
    }
  }
  Send(*obstacles);
  for (const AdsbVehicle& a : adsb) Send(a);
  std::lock_guard lock(mu_);
  ++obstacle_sent_;
  adsb_sent_ += adsb.size();
}

void Bridge::RequestStreams(Clock::time_point now) {
  std::vector<CommandLong> requests;
  {
    std::lock_guard lock(mu_);
    if (!autopilot_ || autopilot_silent_ || now - last_request_ < std::chrono::seconds(5)) return;
    last_request_ = now;
    for (const WantedMessage& w : kWanted) {
      const auto it = last_received_.find(w.id);
      if (it != last_received_.end() && now - it->second < std::chrono::seconds(2)) continue;
      requests.push_back(
          SetMessageInterval(autopilot_->first, autopilot_->second, w.id, w.interval_us));
    }
  }
  for (const CommandLong& c : requests) Send(c);
}

void Bridge::Tick(Clock::time_point now) {
  SendObstacles(now);
  RequestStreams(now);
  std::lock_guard lock(mu_);
  if (autopilot_ && !autopilot_silent_ && now - autopilot_heard_ > std::chrono::seconds(3)) {
    autopilot_silent_ = true;
    Log("warn", "autopilot_silent",
        {{"system_id", Str(autopilot_->first)},
         {"effect",
          "no vehicle states published: the server's georeferencing reports them stale"}});
  }
}

void Bridge::LogStatus() {
  std::shared_ptr<Link> link = CurrentLink();
  std::lock_guard lock(mu_);
  const bool pose_fresh =
      joiner_.last_position_ns() > 0 && UnixNowNs() - joiner_.last_position_ns() < 1'000'000'000;
  Log("info", "status",
      {{"link", link ? link->Describe() : "down"},
       {"autopilot", !autopilot_         ? "unseen"
                     : autopilot_silent_ ? "silent"
                                         : "ok"},
       {"obstacles", obstacles_flowing_ ? "flowing" : "stopped"},
       {"frames_in", Str(frames_in_)},
       {"obstacle_distance_sent", Str(obstacle_sent_)},
       {"adsb_sent", Str(adsb_sent_)},
       {"heartbeats_sent", Str(heartbeats_sent_)},
       {"messages_in", Str(messages_in_)},
       {"crc_errors", Str(parser_stats_.crc_errors)},
       {"signed_dropped", Str(parser_stats_.signed_or_unsupported)},
       {"pose", !pose_fresh                 ? "none"
                : joiner_.waiting().empty() ? "ok"
                                            : joiner_.waiting()},
       {"time_source", joiner_.time_source()},
       {"last_rejected", joiner_.rejected()},
       {"states_published", Str(states_published_)},
       {"states_dropped", Str(states_dropped_)},
       {"geo", v1::GeoStatus_Name(geo_status_)},
       {"geo_message", geo_message_},
       {"stream_gaps", Str(stream_gaps_)},
       {"send_errors", Str(send_errors_)},
       {"link_reopens", Str(link_reopens_)}});
}

int Bridge::Run() {
  v1::GetStatusResponse status;
  if (client_.GetStatus(&status).ok()) {
    adsb_.set_simulated(status.source().rfind("synthetic", 0) == 0);
  }
  OpenLinkNow();  // else the link loop retries every second
  std::promise<void> stream_ended;
  std::future<void> stream_done = stream_ended.get_future();
  std::thread stream([this, &stream_ended] {
    NameThisThread("stevi-mav-strm");
    StreamLoop();
    stream_ended.set_value();
  });
  std::thread reader([this] {
    NameThisThread("stevi-mav-link");
    LinkLoop();
  });
  std::thread publisher([this] {
    NameThisThread("stevi-mav-pub");
    PublishLoop();
  });
  const auto period = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(1.0 / args_.rate_hz));
  const auto status_period = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(args_.status_every_s));
  auto next = Clock::now();
  auto next_heartbeat = next;
  auto next_status = next + status_period;
  Heartbeat heartbeat;
  heartbeat.type = kMavTypeOnboardController;
  heartbeat.autopilot = kMavAutopilotInvalid;
  heartbeat.system_status = kMavStateActive;
  while (true) {
    {
      std::unique_lock lock(mu_);
      if (cv_.wait_until(lock, next, [this] { return stop_; })) break;
    }
    const auto now = Clock::now();
    next += period;
    if (next < now) next = now + period;  // fell behind (a stalled link): no burst
    if (now >= next_heartbeat) {
      Send(heartbeat);
      std::lock_guard lock(mu_);
      ++heartbeats_sent_;
      next_heartbeat += std::chrono::seconds(1);
    }
    Tick(now);
    if (now >= next_status) {
      LogStatus();
      next_status += status_period;
    }
  }
  // A Cancel() that comes before StreamTracks() begins is forgotten: repeat it until the stream
  // thread is done.
  do {
    client_.Cancel();
  } while (stream_done.wait_for(milliseconds(100)) != std::future_status::ready);
  if (std::shared_ptr<Link> link = CurrentLink()) link->Interrupt();
  stream.join();
  reader.join();
  publisher.join();
  LogStatus();
  return 0;
}

void Bridge::Stop() {
  stopping_ = true;
  {
    std::lock_guard lock(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  client_.Cancel();
  if (std::shared_ptr<Link> link = CurrentLink()) link->Interrupt();
}

}  // namespace stevi::client::mavlink
