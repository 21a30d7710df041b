// FoxgloveServer's WebSocket clients (foxglove_server_impl.h), from connect to close: the bounded
// send queue and the sender thread, the frames and messages a client sends, and LocalClient, a
// client without a socket.
#include <algorithm>
#include <string>
#include <utility>

#include <civetweb.h>

#include "client/station/foxglove_server_impl.h"
#include "client/lib/thread_name.h"

namespace stevi::station {

using internal::Json;

// ---- queues

void FoxgloveServer::Impl::Enqueue(Client& client, Outgoing message) {
  std::lock_guard lock(client.queue_mutex);
  if (client.closing) return;
  const bool control = message.opcode == MG_WEBSOCKET_OPCODE_TEXT;
  client.queued_bytes += message.data.size();
  client.queue.push_back(std::move(message));
  if (control && ++client.queued_control > kMaxQueuedControlMessages) {
    CloseLocked(client, internal::kClosePolicyViolation, "not reading");
    return;
  }
  while (client.queue.size() > options.queue_messages ||
         client.queued_bytes > options.queue_bytes) {
    auto victim = std::find_if(client.queue.begin(), client.queue.end(),
                               [](const Outgoing& m) { return m.lossy; });
    if (victim == client.queue.end()) {
      victim = std::find_if(client.queue.begin(), client.queue.end(),
                            [](const Outgoing& m) { return m.opcode != MG_WEBSOCKET_OPCODE_TEXT; });
    }
    if (victim == client.queue.end()) break;  // JSON only: kept
    client.queued_bytes -= victim->data.size();
    client.queue.erase(victim);
    messages_dropped.fetch_add(1, std::memory_order_relaxed);
  }
  client.queue_cv.notify_one();
}

void FoxgloveServer::Impl::EnqueueJson(Client& client, const Json& json) {
  Enqueue(client, Outgoing{MG_WEBSOCKET_OPCODE_TEXT, internal::Dump(json), false});
}

void FoxgloveServer::Impl::EnqueueJsonToAll(const Json& json) {
  for (auto& [conn, client] : clients_) {
    if (client->ready) EnqueueJson(*client, json);
  }
}

void FoxgloveServer::Impl::CloseLocked(Client& client, uint16_t code, std::string reason) {
  if (client.closing) return;
  client.closing = true;
  client.close_code = code;
  client.close_reason = std::move(reason);
  client.queue.clear();
  client.queued_bytes = 0;
  client.queued_control = 0;
  client.queue_cv.notify_one();
}

void FoxgloveServer::Impl::Close(Client& client, uint16_t code, std::string reason) {
  std::lock_guard lock(client.queue_mutex);
  CloseLocked(client, code, std::move(reason));
}

void FoxgloveServer::Impl::SenderLoop(Client& client) {
  for (;;) {
    Outgoing message;
    {
      std::unique_lock lock(client.queue_mutex);
      client.queue_cv.wait(lock, [&] { return client.closing || !client.queue.empty(); });
      if (client.closing) break;
      message = std::move(client.queue.front());
      client.queue.pop_front();
      client.queued_bytes -= message.data.size();
      if (message.opcode == MG_WEBSOCKET_OPCODE_TEXT) --client.queued_control;
    }
    // Blocks until the kernel takes the bytes (at most io_timeout_ms, less when stopping).
    const int written =
        mg_websocket_write(client.conn, message.opcode, message.data.data(), message.data.size());
    if (written < 0 || size_t(written) < message.data.size()) {  // the connection is broken
      Close(client, 0, "");
      return;
    }
    messages_sent.fetch_add(1, std::memory_order_relaxed);
    bytes_sent.fetch_add(message.data.size(), std::memory_order_relaxed);
  }
  uint16_t code = 0;
  std::string reason;
  {
    std::lock_guard lock(client.queue_mutex);
    code = client.close_code;
    reason = client.close_reason;
  }
  if (code != 0) {
    const std::string payload = internal::ClosePayload(code, reason);
    mg_websocket_write(client.conn, MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE, payload.data(),
                       payload.size());
  }
}

void FoxgloveServer::Impl::WriteNow(Client& client, int opcode, std::string_view payload) {
  if (client.local) {
    std::lock_guard lock(client.queue_mutex);
    client.written.push_back({opcode, std::string(payload)});
    return;
  }
  mg_websocket_write(client.conn, opcode, payload.data(), payload.size());
}

// ---- a client's messages

void FoxgloveServer::Impl::Warn(Client& client, std::string_view message) {
  EnqueueJson(client, internal::Status(1, message, ""));
}

void FoxgloveServer::Impl::HandleText(Client& client, std::string_view text) {
  const internal::ClientMessage message = internal::ParseClientMessage(text);
  switch (message.op) {
    case internal::ClientMessage::Op::kNone: Warn(client, message.warning); return;
    case internal::ClientMessage::Op::kSubscribe: Subscribe(client, message.items); return;
    case internal::ClientMessage::Op::kUnsubscribe: Unsubscribe(client, message.items); return;
  }
}

void FoxgloveServer::Impl::Subscribe(Client& client,
                                     const std::vector<internal::SubscriptionItem>& items) {
  std::vector<std::string> problems;
  ChangeSubscriptions([&](Changes& changes) {
    for (const internal::SubscriptionItem& item : items) {
      std::string problem = item.problem.empty()
                                ? channels_.Subscribe(client, item.id, item.channel, changes)
                                : item.problem;
      if (!problem.empty()) problems.push_back(std::move(problem));
    }
  });
  for (const std::string& problem : problems) Warn(client, "subscribe: " + problem);
}

void FoxgloveServer::Impl::Unsubscribe(Client& client,
                                       const std::vector<internal::SubscriptionItem>& items) {
  std::vector<std::string> problems;
  ChangeSubscriptions([&](Changes& changes) {
    for (const internal::SubscriptionItem& item : items) {
      std::string problem =
          item.problem.empty() ? channels_.Unsubscribe(client, item.id, changes) : item.problem;
      if (!problem.empty()) problems.push_back(std::move(problem));
    }
  });
  for (const std::string& problem : problems) Warn(client, "unsubscribe: " + problem);
}

// ---- a WebSocket client's life

int FoxgloveServer::Impl::Connect(const mg_connection* conn) {
  // Checked again under the lock: two clients may have passed Authorize together. This one is
  // then closed without an HTTP answer.
  if (!internal::OffersOurSubprotocol(mg_get_header(conn, "Sec-WebSocket-Protocol"))) return 1;
  std::lock_guard lock(mutex_);
  if (stopped_ || clients_.size() >= options.max_clients) return 1;
  auto client = std::make_unique<Client>();
  client->conn_id = conn;
  client->remote = internal::RemoteAddress(mg_get_request_info(conn));
  mg_set_user_connection_data(conn, client.get());
  const Client* key = client.get();
  clients_.emplace(key, std::move(client));
  return 0;
}

void FoxgloveServer::Impl::Ready(mg_connection* conn) {
  auto* client = static_cast<Client*>(mg_get_user_connection_data(conn));
  if (client == nullptr) return;
  client->conn = conn;
  client->sender = std::thread([this, client] {
    client::NameThisThread("stevi-ws-send");
    SenderLoop(*client);
  });
  std::lock_guard lock(mutex_);
  Greet(*client);
}

void FoxgloveServer::Impl::Greet(Client& client) {
  client.ready = true;
  EnqueueJson(client, internal::ServerInfo(options.name, session_id));
  if (!channels_.empty()) EnqueueJson(client, internal::Advertise(channels_.Adverts()));
}

int FoxgloveServer::Impl::Data(mg_connection* conn, int bits, char* bytes, size_t size) {
  auto* client = static_cast<Client*>(mg_get_user_connection_data(conn));
  if (client == nullptr) return 0;
  return Receive(*client, bits, bytes, size);
}

int FoxgloveServer::Impl::Receive(Client& client, int bits, const char* bytes, size_t size) {
  {
    std::lock_guard lock(client.queue_mutex);
    if (client.closing) return 0;
  }
  using Kind = internal::Received::Kind;
  const internal::Received received = internal::Reassemble(
      client.incoming, bits, std::string_view(bytes, size), options.max_incoming_message_bytes);
  switch (received.kind) {
    case Kind::kClose:
      // The closing handshake (RFC 6455 5.5.1): answer with a Close frame (CloseAnswer), then
      // let civetweb close the connection. The sender stops first; a write in flight finishes
      // before ours (civetweb locks the connection for each frame).
      Close(client, 0, "");
      WriteNow(client, MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE, received.data);
      return 0;
    case Kind::kControl:
    case Kind::kPartial: return 1;
    case Kind::kOrphanContinuation:
      Warn(client, "a continuation frame without a message to continue");
      return 1;
    case Kind::kUnknownOpcode:
      Warn(client, "unknown WebSocket opcode " + std::to_string(received.opcode));
      return 1;
    case Kind::kTooBig:
      Close(client, internal::kCloseMessageTooBig,
            "message larger than " + std::to_string(options.max_incoming_message_bytes) + " bytes");
      return 0;
    case Kind::kMessage: break;
  }
  if (received.opcode == MG_WEBSOCKET_OPCODE_BINARY) {
    Warn(client, "binary client messages are not accepted: this server offers no clientPublish");
  } else {
    HandleText(client, received.data);
  }
  return 1;
}

void FoxgloveServer::Impl::Closed(const mg_connection* conn) {
  auto* client = static_cast<Client*>(mg_get_user_connection_data(conn));
  if (client == nullptr) return;
  Disconnect(*client);
  mg_set_user_connection_data(conn, nullptr);
}

void FoxgloveServer::Impl::Disconnect(Client& client) {
  Close(client, 0, "");
  if (client.sender.joinable()) client.sender.join();
  std::unique_ptr<Client> owned;
  ChangeSubscriptions([&](Changes& changes) {
    channels_.UnsubscribeAll(client, changes);
    auto it = clients_.find(&client);
    if (it != clients_.end()) {
      owned = std::move(it->second);
      clients_.erase(it);
    }
  });
}

// ---- LocalClient

struct FoxgloveServer::LocalClient::State {
  Impl* server = nullptr;
  Impl::Client* client = nullptr;  // owned by the server's clients_
};

FoxgloveServer::LocalClient::LocalClient(std::unique_ptr<State> state) : state_(std::move(state)) {}

FoxgloveServer::LocalClient::~LocalClient() { state_->server->Disconnect(*state_->client); }

bool FoxgloveServer::LocalClient::Receive(uint8_t bits, std::string_view payload) {
  return state_->server->Receive(*state_->client, bits, payload.data(), payload.size()) != 0;
}

std::vector<FoxgloveServer::LocalClient::Frame> FoxgloveServer::LocalClient::TakeSent() {
  Impl::Client& client = *state_->client;
  std::lock_guard lock(client.queue_mutex);
  std::vector<Frame> sent;
  for (Impl::Outgoing& message : client.queue) {
    sent.push_back({message.opcode, std::move(message.data)});
  }
  client.queue.clear();
  client.queued_bytes = 0;
  client.queued_control = 0;
  if (client.closing && client.close_code != 0) {  // what the sender sends as it ends
    sent.push_back({MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE,
                    internal::ClosePayload(client.close_code, client.close_reason)});
    client.close_code = 0;
  }
  for (Frame& frame : client.written) sent.push_back(std::move(frame));
  client.written.clear();
  return sent;
}

std::unique_ptr<FoxgloveServer::LocalClient> FoxgloveServer::ConnectLocal() {
  auto client = std::make_unique<Impl::Client>();
  client->local = true;
  client->remote = "local";
  auto state = std::make_unique<LocalClient::State>();
  state->server = impl_.get();
  state->client = client.get();
  std::lock_guard lock(impl_->mutex_);
  impl_->Greet(*client);
  const Impl::Client* key = client.get();
  impl_->clients_.emplace(key, std::move(client));
  return std::unique_ptr<LocalClient>(new LocalClient(std::move(state)));
}

}  // namespace stevi::station
