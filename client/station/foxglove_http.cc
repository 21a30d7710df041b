// FoxgloveServer's HTTP side (foxglove_server_impl.h): the WebSocket admission answered in HTTP
// (the access token, the subprotocol, the client limit), HTTP requests read from civetweb, the
// access token under /api/, and the handlers by path prefix.
#include <strings.h>

#include <algorithm>
#include <cctype>
#include <cstring>
#include <exception>
#include <string>
#include <utility>

#include <civetweb.h>

#include "client/station/foxglove_server_impl.h"

namespace stevi::station {
namespace {

using internal::Json;

// Compares in time independent of where the strings differ.
bool SameSecret(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  unsigned char diff = 0;
  for (size_t i = 0; i < a.size(); ++i) diff |= uint8_t(a[i]) ^ uint8_t(b[i]);
  return diff == 0;
}

bool IsWebSocketUpgrade(const mg_connection* conn) {
  const char* upgrade = mg_get_header(conn, "Upgrade");
  return upgrade != nullptr && strcasecmp(upgrade, "websocket") == 0;
}

// The token of an "Authorization: Bearer T" header's value, or nullopt.
std::optional<std::string> BearerToken(const char* auth) {
  if (auth == nullptr) return std::nullopt;
  std::string_view value(auth);
  constexpr std::string_view kBearer = "Bearer ";
  if (value.size() < kBearer.size() || strncasecmp(value.data(), kBearer.data(), 7) != 0) {
    return std::nullopt;
  }
  return std::string(value.substr(kBearer.size()));
}

// The token a WebSocket upgrade carries: "Authorization: Bearer T", else ?token=T; or nullopt.
std::optional<std::string> UpgradeToken(const mg_connection* conn) {
  std::optional<std::string> token = BearerToken(mg_get_header(conn, "Authorization"));
  if (!token) {
    const char* query = mg_get_request_info(conn)->query_string;
    if (query != nullptr) {
      std::string value(1024, '\0');
      const int n = mg_get_var(query, strlen(query), "token", value.data(), value.size());
      if (n >= 0) token = value.substr(0, size_t(n));
      if (n == -2) token = std::string();  // too long to be ours
    }
  }
  return token;
}

int SendHttp(mg_connection* conn, const HttpResponse& response) {
  mg_response_header_start(conn, response.status);
  mg_response_header_add(conn, "Content-Type", response.content_type.c_str(), -1);
  mg_response_header_add(conn, "Content-Length", std::to_string(response.body.size()).c_str(), -1);
  mg_response_header_add(conn, "Cache-Control", "no-store", -1);
  for (const auto& [name, value] : response.headers) {
    // A handler's header with a line break would split the response: dropped.
    if (name.find_first_of("\r\n:") != std::string::npos ||
        value.find_first_of("\r\n") != std::string::npos) {
      continue;
    }
    mg_response_header_add(conn, name.c_str(), value.c_str(), -1);
  }
  mg_response_header_send(conn);
  const mg_request_info* info = mg_get_request_info(conn);
  if (!response.body.empty() && strcmp(info->request_method, "HEAD") != 0) {
    mg_write(conn, response.body.data(), response.body.size());
  }
  return response.status;
}

// A refusal of a WebSocket upgrade, written raw: civetweb's response-header functions refuse a
// connection it has marked as WebSocket (1.15). The connection closes after it.
int RefuseUpgrade(mg_connection* conn, const HttpResponse& response) {
  std::string text = "HTTP/1.1 " + std::to_string(response.status) + " " +
                     mg_get_response_code_text(conn, response.status) +
                     "\r\nContent-Type: " + response.content_type +
                     "\r\nContent-Length: " + std::to_string(response.body.size()) +
                     "\r\nConnection: close\r\n";
  for (const auto& [name, value] : response.headers) text += name + ": " + value + "\r\n";
  text += "\r\n" + response.body;
  mg_write(conn, text.data(), text.size());
  return response.status;
}

HttpResponse JsonError(int status, std::string_view code, std::string_view message) {
  HttpResponse response;
  response.status = status;
  response.body = internal::Dump(Json{{"code", code}, {"message", message}});
  return response;
}

// A request's method, path, query, peer and headers (names in lower case; a repeated header's
// values joined with ", "); no body.
HttpRequest RequestHead(const mg_request_info* info) {
  HttpRequest request;
  request.method = info->request_method != nullptr ? info->request_method : "";
  request.path = info->local_uri != nullptr ? info->local_uri : "";
  request.query = info->query_string != nullptr ? info->query_string : "";
  request.remote = internal::RemoteAddress(info);
  for (int i = 0; i < info->num_headers; ++i) {
    std::string name(info->http_headers[i].name);
    std::transform(name.begin(), name.end(), name.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    const std::string value(info->http_headers[i].value);
    auto [it, inserted] = request.headers.emplace(name, value);
    if (!inserted) it->second += ", " + value;
  }
  return request;
}

}  // namespace

std::string internal::RemoteAddress(const mg_request_info* info) {
  const std::string address(info->remote_addr);
  return (address.find(':') != std::string::npos ? "[" + address + "]" : address) + ":" +
         std::to_string(info->remote_port);
}

int FoxgloveServer::Impl::Authorize(mg_connection* conn) {
  if (!IsWebSocketUpgrade(conn)) return 1;
  if (!options.access_token.empty()) {
    const std::optional<std::string> token = UpgradeToken(conn);
    if (!token) {
      RefuseUpgrade(conn, JsonError(401, "UNAUTHENTICATED",
                                    "this station needs its access token (?token=T)"));
      return 0;
    }
    if (!SameSecret(*token, options.access_token)) {
      RefuseUpgrade(conn, JsonError(403, "PERMISSION_DENIED", "wrong access token"));
      return 0;
    }
  }
  if (!internal::OffersOurSubprotocol(mg_get_header(conn, "Sec-WebSocket-Protocol"))) {
    RefuseUpgrade(conn, JsonError(400, "INVALID_ARGUMENT",
                                  "Sec-WebSocket-Protocol must offer foxglove.websocket.v1 or "
                                  "foxglove.sdk.v1"));
    return 0;
  }
  {
    std::lock_guard lock(mutex_);
    if (clients_.size() >= options.max_clients) {
      RefuseUpgrade(conn, JsonError(503, "UNAVAILABLE",
                                    "too many WebSocket clients (" +
                                        std::to_string(options.max_clients) + ")"));
      return 0;
    }
  }
  return 1;
}

int FoxgloveServer::Impl::Http(mg_connection* conn) {
  const mg_request_info* info = mg_get_request_info(conn);
  HttpRequest request = RequestHead(info);
  if (std::optional<HttpResponse> refusal = RefuseAccess(request)) {
    return SendHttp(conn, *refusal);
  }
  if (std::optional<HttpResponse> refusal = ReadBody(conn, info, request)) {
    return SendHttp(conn, *refusal);
  }
  return SendHttp(conn, Route(request));
}

std::optional<HttpResponse> FoxgloveServer::Impl::ReadBody(mg_connection* conn,
                                                           const mg_request_info* info,
                                                           HttpRequest& request) const {
  // Refused unread when its declared length is too large; otherwise read up to one byte past the
  // limit (a chunked body declares nothing).
  const auto transfer = request.headers.find("transfer-encoding");
  const bool chunked = transfer != request.headers.end() && transfer->second != "identity";
  const HttpResponse too_large = JsonError(
      413, "RESOURCE_EXHAUSTED",
      "request body larger than " + std::to_string(options.max_request_body_bytes) + " bytes");
  if (info->content_length > 0 && uint64_t(info->content_length) > options.max_request_body_bytes) {
    mg_disable_connection_keep_alive(conn);
    return too_large;
  }
  if (info->content_length > 0 || chunked) {
    char buffer[16384];
    for (;;) {
      const int n = mg_read(conn, buffer, sizeof buffer);
      if (n <= 0) break;
      request.body.append(buffer, size_t(n));
      if (request.body.size() > options.max_request_body_bytes) {
        mg_disable_connection_keep_alive(conn);
        return too_large;
      }
    }
  }
  return std::nullopt;
}

std::optional<HttpResponse> FoxgloveServer::Impl::RefuseAccess(const HttpRequest& request) const {
  if (options.access_token.empty() || !request.path.starts_with("/api/")) return std::nullopt;
  const auto auth = request.headers.find("authorization");
  std::optional<std::string> token;
  if (auth != request.headers.end()) token = BearerToken(auth->second.c_str());
  if (!token) {
    HttpResponse response = JsonError(401, "UNAUTHENTICATED",
                                      "this station needs its access token "
                                      "(Authorization: Bearer T)");
    response.headers.emplace_back("WWW-Authenticate", "Bearer");
    return response;
  }
  if (!SameSecret(*token, options.access_token)) {
    return JsonError(403, "PERMISSION_DENIED", "wrong access token");
  }
  return std::nullopt;
}

HttpResponse FoxgloveServer::Impl::Route(const HttpRequest& request) const {
  HttpHandler handler;
  {
    std::lock_guard lock(mutex_);
    // Keys in descending order: a longer prefix comes before its own prefixes.
    for (const auto& [prefix, candidate] : handlers_) {
      if (request.path.starts_with(prefix)) {
        handler = candidate;
        break;
      }
    }
  }
  if (!handler) return JsonError(404, "NOT_FOUND", "nothing at " + internal::Quote(request.path));
  try {
    return handler(request);
  } catch (const std::exception& e) {
    return JsonError(500, "INTERNAL", e.what());
  } catch (...) {
    return JsonError(500, "INTERNAL", "unknown exception");
  }
}

HttpResponse FoxgloveServer::HandleHttp(const HttpRequest& request) const {
  if (std::optional<HttpResponse> refusal = impl_->RefuseAccess(request)) return *refusal;
  return impl_->Route(request);
}

void FoxgloveServer::AddHttpHandler(std::string path_prefix, HttpHandler handler) {
  std::lock_guard lock(impl_->mutex_);
  impl_->handlers_[std::move(path_prefix)] = std::move(handler);
}

}  // namespace stevi::station
