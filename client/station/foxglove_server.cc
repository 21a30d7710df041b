// FoxgloveServer (foxglove_server.h): starting civetweb on the listen address and stopping it,
// the channels and publishing. A WebSocket client's life is in foxglove_connection.cc, HTTP in
// foxglove_http.cc, both on FoxgloveServer::Impl (foxglove_server_impl.h).
#include "client/station/foxglove_server.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <iterator>
#include <mutex>
#include <thread>

#include <civetweb.h>

#include "client/station/foxglove_server_impl.h"
#include "client/lib/thread_name.h"

namespace stevi::station {
namespace {

using internal::Json;

// civetweb keeps the pointer: static storage.
mg_websocket_subprotocols kSubprotocols = {int(std::size(internal::kSubprotocolNames)),
                                           internal::kSubprotocolNames};

// HOST:PORT to civetweb's listening_ports form; "" and `error` set when malformed.
std::string ListeningPorts(const std::string& listen, std::string& error) {
  std::string host;
  std::string port;
  bool ipv6 = false;
  if (!listen.empty() && listen.front() == '[') {
    const size_t close = listen.find(']');
    if (close == std::string::npos || close + 1 >= listen.size() || listen[close + 1] != ':') {
      error = "expected [IPV6]:PORT";
      return "";
    }
    host = listen.substr(1, close - 1);
    port = listen.substr(close + 2);
    ipv6 = true;
  } else {
    const size_t colon = listen.rfind(':');
    if (colon == std::string::npos) {
      error = "expected HOST:PORT";
      return "";
    }
    host = listen.substr(0, colon);
    port = listen.substr(colon + 1);
  }
  if (port.empty() || port.size() > 5 ||
      !std::all_of(port.begin(), port.end(), [](char c) { return c >= '0' && c <= '9'; }) ||
      std::stoi(port) > 65535) {
    error = "the port must be 0..65535";
    return "";
  }
  if (host == "localhost") host = "127.0.0.1";
  unsigned char address[16];
  if (ipv6) {
    if (inet_pton(AF_INET6, host.c_str(), address) != 1) {
      error = "not an IPv6 address";
      return "";
    }
    if (mg_check_feature(MG_FEATURES_IPV6) == 0) {
      error = "this civetweb has no IPv6";
      return "";
    }
    return "[" + host + "]:" + std::to_string(std::stoi(port));
  }
  if (inet_pton(AF_INET, host.c_str(), address) != 1) {
    error = "the host must be an IPv4 address, [IPv6] or localhost";
    return "";
  }
  return host + ":" + std::to_string(std::stoi(port));
}

// civetweb's listening_ports for valid options; "" and `error` set otherwise (`where`: the
// address, for the address's problems).
std::string CheckOptions(const FoxgloveServerOptions& options, const std::string& where,
                         std::string& error) {
  std::string problem;
  const std::string ports = ListeningPorts(options.listen, problem);
  if (ports.empty()) {
    error = where + problem;
    return "";
  }
  if (options.max_clients == 0 || options.queue_messages == 0 || options.queue_bytes == 0 ||
      options.io_timeout_ms <= 0) {
    error = "max_clients, queue_messages, queue_bytes and io_timeout_ms must be positive";
    return "";
  }
  if (mg_check_feature(MG_FEATURES_WEBSOCKET) == 0) {
    error = "this civetweb was built without WebSocket support";
    return "";
  }
  return ports;
}

// Opens and at once closes a TCP connection to HOST:PORT (HOST "1.2.3.4" or "[::1]").
void PokeListener(const std::string& host, int port) {
  sockaddr_storage address{};
  socklen_t length = 0;
  if (!host.empty() && host.front() == '[') {
    auto* v6 = reinterpret_cast<sockaddr_in6*>(&address);
    v6->sin6_family = AF_INET6;
    v6->sin6_port = htons(uint16_t(port));
    if (inet_pton(AF_INET6, host.substr(1, host.size() - 2).c_str(), &v6->sin6_addr) != 1) return;
    length = sizeof(sockaddr_in6);
  } else {
    auto* v4 = reinterpret_cast<sockaddr_in*>(&address);
    v4->sin_family = AF_INET;
    v4->sin_port = htons(uint16_t(port));
    if (inet_pton(AF_INET, host.c_str(), &v4->sin_addr) != 1) return;
    length = sizeof(sockaddr_in);
  }
  const int fd = socket(address.ss_family, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return;
  connect(fd, reinterpret_cast<const sockaddr*>(&address), length);
  close(fd);
}

}  // namespace

bool FoxgloveServer::Impl::Listen(const std::string& ports, const std::string& where,
                                  std::string& error) {
  // Each open WebSocket holds a worker thread; 8 more serve HTTP requests and refusals.
  const std::string threads = std::to_string(options.max_clients + 8);
  const std::string timeout = std::to_string(options.io_timeout_ms);
  const char* config[] = {"listening_ports",
                          ports.c_str(),
                          "num_threads",
                          threads.c_str(),
                          "request_timeout_ms",
                          timeout.c_str(),
                          "websocket_timeout_ms",
                          timeout.c_str(),
                          "enable_websocket_ping_pong",
                          "yes",
                          "enable_keep_alive",
                          "no",
                          nullptr};
  mg_callbacks callbacks{};
  callbacks.log_message = &OnLog;
  mg_init_data init{};
  init.callbacks = &callbacks;
  init.user_data = this;
  init.configuration_options = config;
  char text[256] = "";
  unsigned code = 0;
  mg_error_data start_error{&code, text, sizeof text};
  ctx = mg_start2(&init, &start_error);
  if (ctx == nullptr) {
    error = where + (text[0] != '\0' ? text : "cannot listen");
    return false;
  }
  mg_server_port server_ports[4] = {};
  const int n = mg_get_server_ports(ctx, 4, server_ports);
  port = n > 0 ? server_ports[0].port : 0;
  wake_host = ports.substr(0, ports.rfind(':'));
  if (wake_host == "0.0.0.0") wake_host = "127.0.0.1";
  if (wake_host == "[::]") wake_host = "[::1]";
  return true;
}

void FoxgloveServer::Impl::SetHandlers() {
  mg_set_auth_handler(ctx, "/", &OnAuthorize, this);
  mg_set_websocket_handler_with_subprotocols(ctx, "/", &kSubprotocols, &OnConnect, &OnReady,
                                             &OnData, &OnClose, this);
  mg_set_request_handler(ctx, "/", &OnHttp, this);
}

FoxgloveServer::FoxgloveServer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

FoxgloveServer::~FoxgloveServer() { Stop(); }

std::unique_ptr<FoxgloveServer> FoxgloveServer::Start(FoxgloveServerOptions options,
                                                      std::string& error) {
  const std::string where = "station listen address \"" + options.listen + "\": ";
  const std::string ports = CheckOptions(options, where, error);
  if (ports.empty()) return nullptr;
  static std::once_flag library_once;
  std::call_once(library_once, [] { mg_init_library(0); });

  auto impl = std::make_unique<Impl>();
  impl->options = std::move(options);
  impl->session_id = std::to_string(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                        std::chrono::system_clock::now().time_since_epoch())
                                        .count());
  if (!impl->Listen(ports, where, error)) return nullptr;
  impl->SetHandlers();
  return std::unique_ptr<FoxgloveServer>(new FoxgloveServer(std::move(impl)));
}

std::unique_ptr<FoxgloveServer> FoxgloveServer::StartUnbound(FoxgloveServerOptions options) {
  auto impl = std::make_unique<Impl>();
  impl->options = std::move(options);
  impl->session_id = "unbound";
  return std::unique_ptr<FoxgloveServer>(new FoxgloveServer(std::move(impl)));
}

int FoxgloveServer::port() const { return impl_->port; }

uint32_t FoxgloveServer::AddChannel(ChannelSpec spec) {
  std::lock_guard lock(impl_->mutex_);
  const uint32_t id = impl_->channels_.Add(std::move(spec));
  impl_->EnqueueJsonToAll(internal::Advertise(Json::array({impl_->channels_.Find(id)->advert})));
  return id;
}

void FoxgloveServer::RemoveChannel(uint32_t channel) {
  impl_->ChangeSubscriptions([&](Impl::Changes& changes) {
    if (!impl_->channels_.Remove(channel, changes)) return;
    impl_->EnqueueJsonToAll(internal::Unadvertise(channel));
  });
}

bool FoxgloveServer::HasSubscribers(uint32_t channel) const {
  std::lock_guard lock(impl_->mutex_);
  return impl_->channels_.HasSubscribers(channel);
}

void FoxgloveServer::SetSubscriptionListener(std::function<void(uint32_t, bool)> listener) {
  std::lock_guard listener_lock(impl_->listener_mutex_);
  std::lock_guard lock(impl_->mutex_);
  impl_->listener_ = std::move(listener);
}

void FoxgloveServer::Publish(uint32_t channel, uint64_t log_time_ns, std::string_view payload) {
  std::lock_guard lock(impl_->mutex_);
  const internal::Channel* found = impl_->channels_.Find(channel);
  if (found == nullptr) return;
  for (const auto& [client, subscription] : found->subscribers) {
    Impl::Outgoing message;
    message.opcode = MG_WEBSOCKET_OPCODE_BINARY;
    message.lossy = found->spec.lossy;
    message.data = internal::MessageData(subscription, log_time_ns, payload);
    impl_->Enqueue(*client, std::move(message));
  }
}

void FoxgloveServer::SendStatus(int level, std::string message, std::string id) {
  std::lock_guard lock(impl_->mutex_);
  impl_->EnqueueJsonToAll(internal::Status(level, message, id));
}

FoxgloveServer::Stats FoxgloveServer::stats() const {
  Stats stats;
  {
    std::lock_guard lock(impl_->mutex_);
    stats.clients = impl_->clients_.size();
  }
  stats.messages_sent = impl_->messages_sent.load();
  stats.messages_dropped = impl_->messages_dropped.load();
  stats.bytes_sent = impl_->bytes_sent.load();
  return stats;
}

void FoxgloveServer::Stop() {
  mg_context* ctx = nullptr;
  {
    std::lock_guard lock(impl_->mutex_);
    impl_->stopped_ = true;
    std::swap(ctx, impl_->ctx);
  }
  if (ctx == nullptr) return;
  // mg_stop joins civetweb's threads; each open WebSocket's close handler joins its sender first.
  // civetweb's master thread sees the stop flag only when its poll of the listening socket
  // returns, after up to 2 s: connections to it make that at once.
  std::mutex mutex;
  std::condition_variable cv;
  bool stopped = false;
  std::thread waker([&] {
    client::NameThisThread("stevi-ws-waker");
    std::unique_lock lock(mutex);
    while (!stopped) {
      lock.unlock();
      PokeListener(impl_->wake_host, impl_->port);
      lock.lock();
      cv.wait_for(lock, std::chrono::milliseconds(20), [&] { return stopped; });
    }
  });
  mg_stop(ctx);
  {
    std::lock_guard lock(mutex);
    stopped = true;
  }
  cv.notify_all();
  waker.join();
}

}  // namespace stevi::station
