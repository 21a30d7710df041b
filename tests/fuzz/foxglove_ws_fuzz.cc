// Fuzz target: what Foxglove WebSocket clients send the station, once civetweb has decoded each
// frame: the frames (opcode, FIN; reassembly of fragments, the size limit, Close, Ping, Pong,
// unknown opcodes) and the messages (JSON operations: subscribe, unsubscribe, the unsupported
// ones, malformed ones; binary messages), through FoxgloveServer::LocalClient, which is served as
// civetweb's handlers serve a connection. Interleaved with the station's own calls: channels added
// and removed, messages published, status sent. A fresh server (listening nowhere) per input, so
// that channel ids are the same on every run.
//
// Input: records, each a kind byte, a length (two bytes, little-endian) and that many bytes of
// payload (fewer at the end of the input). Kind with bit 7 clear: a frame from client (bit 5) 0 or
// 1, its opcode the low four bits, FIN bit 4. Kind with bit 7 set, by its low three bits: 0 adds
// a channel (topic: the payload; lossy: bit 3), 1 removes channel payload[0], 2 publishes the
// payload on every channel, 3 sends a status (level payload[0] % 3), 4 reconnects client (bit 5).
// Checked besides the sanitizers:
//   - a client's first message is serverInfo; every text message the server sends is a JSON object
//     with a known op, statuses have a level 0..2 and a message;
//   - a complete text message that is not JSON, and every binary message, gets a warning status;
//   - a published message reaches each client at most once per channel, with one subscription id
//     per channel and the published time and payload; at least one client gets it when the
//     channel has subscribers;
//   - the subscription listener is told true and false in turn per channel, and agrees with
//     HasSubscribers; after every client has gone, no channel has subscribers;
//   - a Close frame the server sends is empty or holds a status code a server may send
//     (RFC 6455 7.4) and at most 125 bytes; after it the server sends nothing and takes nothing.
#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include "client/station/foxglove_server.h"
#include "tests/fuzz/require.h"

namespace st = stevi::station;
using Json = nlohmann::json;

namespace {

constexpr size_t kMaxChannels = 16;

using stevi::fuzz::Require;

bool SendableCloseCode(unsigned code) {
  return (code >= 1000 && code <= 1003) || (code >= 1007 && code <= 1014) ||
         (code >= 3000 && code <= 4999);
}

struct Peer {
  std::unique_ptr<st::FoxgloveServer::LocalClient> client;
  bool greeted = false;
  bool refused = false;  // Receive returned false: the connection ends
  bool closed = false;   // the server sent a Close
};

class Session {
 public:
  Session() {
    st::FoxgloveServerOptions options;
    options.max_incoming_message_bytes = 4096;
    options.queue_messages = 64;
    server_ = st::FoxgloveServer::StartUnbound(options);
    server_->SetSubscriptionListener([this](uint32_t channel, bool subscribed) {
      bool& state = subscribed_[channel];
      Require(state != subscribed);  // true and false in turn, starting with true
      state = subscribed;
    });
    AddChannel("/rig1/tracks", false);
    AddChannel("/rig1/image/annotated", true);
    AddChannel("/rig1/status", false);
    for (Peer& peer : peers_) Connect(peer);
  }
  ~Session() {
    for (Peer& peer : peers_) peer.client.reset();
    for (uint32_t channel : channels_) Require(!server_->HasSubscribers(channel));
    for (const auto& [channel, subscribed] : subscribed_) Require(!subscribed);
    server_.reset();
  }
  Session(const Session&) = delete;
  Session& operator=(const Session&) = delete;

  void Record(uint8_t kind, std::string_view payload) {
    if ((kind & 0x80) == 0) {
      Frame(peers_[(kind >> 5) & 1], kind, payload);
    } else {
      switch (kind & 7) {
        case 0:
          if (channels_.size() < kMaxChannels) AddChannel(std::string(payload), (kind & 8) != 0);
          break;
        case 1:
          if (!payload.empty()) server_->RemoveChannel(uint8_t(payload[0]));
          channels_.erase(payload.empty() ? 0 : uint8_t(payload[0]));
          break;
        case 2: Publish(payload); break;
        case 3:
          server_->SendStatus(payload.empty() ? 0 : uint8_t(payload[0]) % 3, std::string(payload));
          break;
        case 4: Connect(peers_[(kind >> 5) & 1]); break;
        default: break;
      }
    }
    for (Peer& peer : peers_) CheckSent(peer, Drain(peer));
    for (uint32_t channel : channels_) {
      const auto it = subscribed_.find(channel);
      Require(server_->HasSubscribers(channel) == (it != subscribed_.end() && it->second));
    }
  }

 private:
  void AddChannel(std::string topic, bool lossy) {
    st::ChannelSpec spec;
    spec.topic = std::move(topic);
    spec.encoding = lossy ? "protobuf" : "json";
    spec.schema_name = "fuzz.Message";
    spec.schema = lossy ? std::string("\x0a\x03\x61\x62\x63", 5) : R"({"type":"object"})";
    spec.lossy = lossy;
    channels_.insert(server_->AddChannel(std::move(spec)));
  }

  void Connect(Peer& peer) {
    peer.client.reset();
    peer = Peer{};
    peer.client = server_->ConnectLocal();
  }

  static std::vector<st::FoxgloveServer::LocalClient::Frame> Drain(Peer& peer) {
    if (!peer.client) return {};
    return peer.client->TakeSent();
  }

  void Frame(Peer& peer, uint8_t kind, std::string_view payload) {
    const int opcode = kind & 0x0f;
    const bool fin = (kind & 0x10) != 0;
    std::vector<st::FoxgloveServer::LocalClient::Frame> before = Drain(peer);
    CheckSent(peer, before);
    if (!peer.client) Connect(peer);  // a new connection
    const bool was_closed = peer.closed || peer.refused;
    const bool kept = peer.client->Receive(uint8_t(opcode | (fin ? 0x80 : 0)), payload);
    if (was_closed) Require(!kept);
    if (!kept) peer.refused = true;
    std::vector<st::FoxgloveServer::LocalClient::Frame> sent = Drain(peer);
    // A whole message in one frame that is no JSON object with an op, or binary: a warning.
    const bool whole = fin && (opcode == 1 || opcode == 2) && payload.size() <= 4096;
    if (kept && whole) {
      const Json json = Json::parse(payload, nullptr, false);
      const bool bad = opcode == 2 || json.is_discarded() || !json.is_object() ||
                       !json.contains("op") || !json["op"].is_string();
      if (bad) Require(HasStatus(sent));
    }
    CheckSent(peer, sent);
    if (!kept) peer.client.reset();  // civetweb closes the connection
  }

  static bool HasStatus(const std::vector<st::FoxgloveServer::LocalClient::Frame>& sent) {
    for (const auto& frame : sent) {
      const Json json = Json::parse(frame.payload, nullptr, false);
      if (frame.opcode == 1 && json.is_object() && json.value("op", "") == "status") return true;
    }
    return false;
  }

  void CheckSent(Peer& peer, const std::vector<st::FoxgloveServer::LocalClient::Frame>& sent) {
    for (const auto& frame : sent) {
      if (frame.opcode == 8) {  // one Close, the last frame
        Require(!peer.closed);
        Require(frame.payload.empty() ||
                (frame.payload.size() >= 2 && frame.payload.size() <= 125 &&
                 SendableCloseCode(unsigned(uint8_t(frame.payload[0])) << 8 |
                                   uint8_t(frame.payload[1]))));
        peer.closed = true;
        continue;
      }
      Require(!peer.closed && !peer.refused);
      if (frame.opcode == 2) continue;  // Message Data: checked by Publish
      Require(frame.opcode == 1);
      const Json json = Json::parse(frame.payload, nullptr, false);
      Require(json.is_object() && json.contains("op") && json["op"].is_string());
      const std::string op = json["op"];
      if (!peer.greeted) Require(op == "serverInfo");
      peer.greeted = true;
      if (op == "status") {
        Require(json.contains("level") && json["level"].is_number_integer());
        const int level = json["level"];
        Require(level >= 0 && level <= 2);
        Require(json.contains("message") && json["message"].is_string());
      } else if (op == "advertise") {
        Require(json.contains("channels") && json["channels"].is_array());
        for (const Json& c : json["channels"]) {
          Require(c.is_object() && c["id"].is_number_unsigned() && c["topic"].is_string() &&
                  c["encoding"].is_string() && c["schemaName"].is_string() &&
                  c["schema"].is_string());
        }
      } else {
        Require(op == "serverInfo" || op == "unadvertise");
      }
    }
  }

  void Publish(std::string_view payload) {
    uint64_t time = 1'700'000'000'000'000'000ULL + payload.size();
    for (Peer& peer : peers_) CheckSent(peer, Drain(peer));
    std::map<uint32_t, size_t> receivers;  // channel -> clients that got it
    std::vector<std::vector<st::FoxgloveServer::LocalClient::Frame>> got(2);
    std::map<uint32_t, uint32_t> time_to_channel;
    for (uint32_t channel : channels_) {
      ++time;
      time_to_channel[uint32_t(time)] = channel;
      server_->Publish(channel, time, payload);
    }
    for (size_t k = 0; k < 2; ++k) {
      Peer& peer = peers_[k];
      const std::vector<st::FoxgloveServer::LocalClient::Frame> sent = Drain(peer);
      std::set<uint32_t> channels_seen, ids_seen;
      for (const auto& frame : sent) {
        if (frame.opcode != 2) continue;
        Require(frame.payload.size() == 13 + payload.size() && frame.payload[0] == 0x01);
        uint32_t id = 0;
        uint64_t t = 0;
        for (int i = 0; i < 4; ++i) id |= uint32_t(uint8_t(frame.payload[1 + i])) << (8 * i);
        for (int i = 0; i < 8; ++i) t |= uint64_t(uint8_t(frame.payload[5 + i])) << (8 * i);
        Require(frame.payload.compare(13, std::string::npos, payload) == 0);
        const auto channel = time_to_channel.find(uint32_t(t));
        Require(channel != time_to_channel.end());
        Require(channels_seen.insert(channel->second).second);  // once per channel
        Require(ids_seen.insert(id).second);                    // one id per channel
        ++receivers[channel->second];
      }
      CheckSent(peer, sent);
    }
    const bool all_open = !peers_[0].closed && !peers_[1].closed;  // no closing client
    for (uint32_t channel : channels_) {
      if (server_->HasSubscribers(channel) && all_open) Require(receivers[channel] >= 1);
      if (!server_->HasSubscribers(channel)) Require(receivers[channel] == 0);
    }
  }

  std::unique_ptr<st::FoxgloveServer> server_;
  std::set<uint32_t> channels_;
  std::map<uint32_t, bool> subscribed_;  // what the listener was told last
  Peer peers_[2];
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  Session session;
  size_t at = 0;
  while (at < size) {
    const uint8_t kind = data[at++];
    size_t n = 0;
    if (at < size) n = data[at++];
    if (at < size) n |= size_t(data[at++]) << 8;
    n = std::min(n, size - at);
    session.Record(kind, std::string_view(reinterpret_cast<const char*>(data) + at, n));
    at += n;
  }
  return 0;
}
