#include "client/station/station.h"

#include <google/protobuf/util/json_util.h>

#include <atomic>
#include <cctype>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <string_view>
#include <utility>

#include "client/advisory/export.h"
#include "proto/foxglove/convert.h"
#include "client/station/web_assets.h"
#include "stevi/v1/station.pb.h"

namespace stevi::station {

namespace pb = google::protobuf;
using to_foxglove::FileDescriptorSetFor;
using to_foxglove::ToCompressedImage;
using to_foxglove::ToImageAnnotations;
using to_foxglove::ToLocationFix;
using to_foxglove::ToSceneUpdate;

struct Station::Rig {
  std::unique_ptr<RigLink> link;
  uint32_t tracks = 0, status = 0, annotated = 0, disparity = 0, left = 0, annotations = 0,
           scene = 0, vehicle = 0;
  // Preview pixels per TrackFrame pixel, of the last preview (for the boxes of /annotations).
  std::atomic<double> preview_scale{1.0};
};

namespace {

std::string ProtoJson(const pb::Message& message) {
  pb::util::JsonPrintOptions options;
  options.preserve_proto_field_names = true;
  options.always_print_primitive_fields = true;
  std::string out;
  (void)pb::util::MessageToJsonString(message, &out, options);
  return out;
}

// JSON text of `json`, with invalid UTF-8 (from a request's path, say) replaced instead of thrown.
std::string Dump(const nlohmann::json& json) {
  return json.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

HttpResponse JsonResponse(int status, std::string body) {
  HttpResponse r;
  r.status = status;
  r.content_type = "application/json";
  r.body = std::move(body);
  return r;
}

HttpResponse ErrorResponse(int status, const std::string& code, const std::string& message) {
  return JsonResponse(status, Dump(nlohmann::json{{"code", code}, {"message", message}}));
}

int HttpStatusOf(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::INVALID_ARGUMENT:
    case grpc::StatusCode::OUT_OF_RANGE: return 400;
    case grpc::StatusCode::UNAUTHENTICATED: return 401;
    case grpc::StatusCode::PERMISSION_DENIED: return 403;
    case grpc::StatusCode::NOT_FOUND: return 404;
    case grpc::StatusCode::ALREADY_EXISTS:
    case grpc::StatusCode::FAILED_PRECONDITION:
    case grpc::StatusCode::ABORTED: return 409;
    case grpc::StatusCode::RESOURCE_EXHAUSTED: return 429;
    case grpc::StatusCode::UNIMPLEMENTED: return 501;
    case grpc::StatusCode::UNAVAILABLE:
    case grpc::StatusCode::DEADLINE_EXCEEDED: return 503;
    default: return 502;
  }
}

// A server's refusal: its code and message, and for INVALID_ARGUMENT each "field: problem" of the
// message as {field, message}, so that the page can show each beside its field.
// Plain matchers for the station's untrusted strings. Not std::regex: libstdc++'s matcher recurses
// once per character, and a few hundred characters overflow a web worker's stack.
bool IsWordChar(char c) { return std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '_'; }

// "field.path: message" (a field name of letters, digits, '_', '.', '[' and ']' not starting with
// a digit, then ": " and a non-empty message): the field and the message.
std::optional<std::pair<std::string, std::string>> SplitFieldProblem(std::string_view part) {
  if (part.empty() || !IsWordChar(part[0]) ||
      std::isdigit(static_cast<unsigned char>(part[0])) != 0) {
    return std::nullopt;
  }
  size_t i = 0;
  while (i < part.size() &&
         (IsWordChar(part[i]) || part[i] == '.' || part[i] == '[' || part[i] == ']')) {
    ++i;
  }
  if (part.substr(i, 2) != ": " || i + 2 >= part.size()) return std::nullopt;
  return std::pair{std::string(part.substr(0, i)), std::string(part.substr(i + 2))};
}

// A relative file path of '/'-separated names of letters, digits, '_' and '-', the last with one
// '.' and an extension of letters and digits ("dist/leaflet.js", "dist/images/marker-icon.png").
bool IsPlainRelativePath(std::string_view rel) {
  const size_t dot = rel.rfind('.');
  if (dot == std::string_view::npos || dot + 1 == rel.size()) return false;
  for (const char c : rel.substr(dot + 1)) {
    if (std::isalnum(static_cast<unsigned char>(c)) == 0) return false;
  }
  bool empty_name = true;
  for (const char c : rel.substr(0, dot)) {
    if (c == '/') {
      if (empty_name) return false;
      empty_name = true;
    } else if (IsWordChar(c) || c == '-') {
      empty_name = false;
    } else {
      return false;
    }
  }
  return !empty_name;
}

// "/api/rigs/rigN/WHAT" (N digits, WHAT of lower-case letters, '_', '.' and '/'): rigN and WHAT.
std::optional<std::pair<std::string, std::string>> SplitRigPath(std::string_view path) {
  constexpr std::string_view kPrefix = "/api/rigs/rig";
  if (!path.starts_with(kPrefix)) return std::nullopt;
  size_t i = kPrefix.size();
  while (i < path.size() && std::isdigit(static_cast<unsigned char>(path[i])) != 0) ++i;
  if (i == kPrefix.size() || i >= path.size() || path[i] != '/' || i + 1 == path.size()) {
    return std::nullopt;
  }
  const std::string_view what = path.substr(i + 1);
  for (const char c : what) {
    if (!((c >= 'a' && c <= 'z') || c == '_' || c == '.' || c == '/')) return std::nullopt;
  }
  return std::pair{std::string(path.substr(kPrefix.size() - 3, i - (kPrefix.size() - 3))),
                   std::string(what)};
}

HttpResponse RpcError(const grpc::Status& status) {
  nlohmann::json body{{"code", client::StatusCodeName(status.error_code())},
                      {"message", status.error_message()}};
  if (status.error_code() == grpc::StatusCode::INVALID_ARGUMENT) {
    nlohmann::json problems = nlohmann::json::array();
    std::string text = status.error_message();
    size_t start = 0;
    while (start <= text.size()) {
      size_t end = text.find("; ", start);
      if (end == std::string::npos) end = text.size();
      const std::string part = text.substr(start, end - start);
      if (const auto field = SplitFieldProblem(part)) {
        problems.push_back({{"field", field->first}, {"message", field->second}});
      } else if (!part.empty()) {
        problems.push_back({{"field", ""}, {"message", part}});
      }
      start = end + 2;
    }
    body["problems"] = problems;
  }
  return JsonResponse(HttpStatusOf(status.error_code()), Dump(body));
}

std::string QueryValue(const std::string& query, const std::string& key) {
  std::istringstream in(query);
  std::string pair;
  while (std::getline(in, pair, '&')) {
    if (pair.rfind(key + "=", 0) == 0) return pair.substr(key.size() + 1);
  }
  return "";
}

std::string HeaderValue(const HttpRequest& request, const std::string& name) {
  const auto it = request.headers.find(name);
  return it == request.headers.end() ? "" : it->second;
}

// Leaflet's files from the Debian package: a plain relative path only.
HttpResponse LeafletFile(const std::string& dir, const std::string& rel) {
  if (!IsPlainRelativePath(rel) || rel.find("..") != std::string::npos) {
    return ErrorResponse(404, "NOT_FOUND", "no such file: /leaflet/" + rel);
  }
  std::ifstream in(dir + "/" + rel, std::ios::binary);
  if (!in) {
    return ErrorResponse(
        404, "NOT_FOUND",
        "/leaflet/" + rel + " is not installed (Debian package libjs-leaflet, " + dir + ")");
  }
  std::ostringstream bytes;
  bytes << in.rdbuf();
  HttpResponse r;
  r.body = bytes.str();
  const std::string ext = rel.substr(rel.rfind('.') + 1);
  r.content_type = ext == "js"    ? "text/javascript"
                   : ext == "css" ? "text/css"
                   : ext == "png" ? "image/png"
                                  : "application/octet-stream";
  r.headers.emplace_back("Cache-Control", "max-age=3600");
  return r;
}

}  // namespace

std::string CheckSiteGeoJson(const std::string& text) {
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded()) return "not JSON";
  if (!j.is_object() || !j.contains("type") || !j["type"].is_string()) {
    return "not a GeoJSON object (no \"type\")";
  }
  static const std::vector<std::string> kTypes = {
      "FeatureCollection", "Feature", "Point",        "MultiPoint",        "LineString",
      "MultiLineString",   "Polygon", "MultiPolygon", "GeometryCollection"};
  const std::string type = j["type"];
  if (std::find(kTypes.begin(), kTypes.end(), type) == kTypes.end()) {
    return "unknown GeoJSON type \"" + type + "\"";
  }
  if (type == "FeatureCollection" && (!j.contains("features") || !j["features"].is_array())) {
    return "a FeatureCollection needs a \"features\" array";
  }
  return "";
}

Station::Station(StationOptions options) : options_(std::move(options)) {}

Station::~Station() { Stop(); }

int Station::port() const { return server_ ? server_->port() : 0; }

HttpResponse Station::HandleHttp(const HttpRequest& request) const {
  return server_->HandleHttp(request);
}

void Station::Stop() {
  for (auto& rig : rigs_) rig->link->Stop();
  if (server_) server_->Stop();
}

void Station::Route(uint32_t channel, bool subscribed) {
  for (auto& rig : rigs_) {
    if (channel == rig->annotated)
      rig->link->SetPreviewWanted(v1::PREVIEW_KIND_ANNOTATED_LEFT, subscribed);
    if (channel == rig->disparity)
      rig->link->SetPreviewWanted(v1::PREVIEW_KIND_DISPARITY, subscribed);
    if (channel == rig->left) rig->link->SetPreviewWanted(v1::PREVIEW_KIND_LEFT, subscribed);
  }
}

std::unique_ptr<Station::Rig> Station::MakeRig(size_t i) {
  FoxgloveServer& web = *server_;
  const auto add_channel = [&web](const std::string& topic, const pb::Descriptor* type,
                                  bool lossy) {
    ChannelSpec spec;
    spec.topic = topic;
    spec.schema_name = type->full_name();
    spec.schema = FileDescriptorSetFor(type);
    spec.lossy = lossy;
    return web.AddChannel(std::move(spec));
  };
  auto rig = std::make_unique<Rig>();
  const std::string name = "rig" + std::to_string(i + 1);
  const std::string p = "/" + name;
  rig->tracks = add_channel(p + "/tracks", v1::TrackFrame::descriptor(), false);
  rig->status = add_channel(p + "/status", v1::StationRigStatus::descriptor(), false);
  rig->annotated =
      add_channel(p + "/image/annotated", foxglove::CompressedImage::descriptor(), true);
  rig->disparity =
      add_channel(p + "/image/disparity", foxglove::CompressedImage::descriptor(), true);
  rig->left = add_channel(p + "/image/left", foxglove::CompressedImage::descriptor(), true);
  rig->annotations =
      add_channel(p + "/annotations", foxglove::ImageAnnotations::descriptor(), false);
  rig->scene = add_channel(p + "/scene", foxglove::SceneUpdate::descriptor(), false);
  rig->vehicle = add_channel(p + "/vehicle", foxglove::LocationFix::descriptor(), false);

  Rig* r = rig.get();
  RigCallbacks callbacks;
  const std::string camera_frame = name + "_camera";
  callbacks.on_frame = [&web, r, camera_frame, name](const v1::TrackFrame& frame) {
    const uint64_t t = static_cast<uint64_t>(frame.capture_unix_time_ns());
    if (web.HasSubscribers(r->tracks)) web.Publish(r->tracks, t, frame.SerializeAsString());
    if (web.HasSubscribers(r->annotations)) {
      web.Publish(r->annotations, t,
                  ToImageAnnotations(frame, r->preview_scale.load()).SerializeAsString());
    }
    if (web.HasSubscribers(r->scene)) {
      web.Publish(r->scene, t, ToSceneUpdate(frame, camera_frame).SerializeAsString());
    }
    foxglove::LocationFix fix;
    if (web.HasSubscribers(r->vehicle) && ToLocationFix(frame, name + "_vehicle", fix)) {
      web.Publish(r->vehicle, t, fix.SerializeAsString());
    }
  };
  callbacks.on_preview = [&web, r, camera_frame](const v1::Preview& preview) {
    if (preview.scale() > 0) r->preview_scale.store(preview.scale());
    const uint32_t ch = preview.kind() == v1::PREVIEW_KIND_ANNOTATED_LEFT ? r->annotated
                        : preview.kind() == v1::PREVIEW_KIND_DISPARITY    ? r->disparity
                                                                          : r->left;
    web.Publish(ch, static_cast<uint64_t>(preview.capture_unix_time_ns()),
                ToCompressedImage(preview, camera_frame).SerializeAsString());
  };
  callbacks.on_status = [&web, r](const v1::StationRigStatus& status) {
    web.Publish(r->status, static_cast<uint64_t>(status.unix_time_ns()),
                status.SerializeAsString());
  };
  client::ClientOptions client = options_.client;
  client.address = options_.servers[i];
  rig->link =
      std::make_unique<RigLink>(name, client, options_.previews, callbacks, options_.export_points);
  return rig;
}

std::unique_ptr<Station> Station::Start(StationOptions options, std::string* error) {
  std::unique_ptr<Station> station(new Station(std::move(options)));
  Station& s = *station;
  std::string start_error;
  s.server_ = FoxgloveServer::Start(s.options_.web, start_error);
  if (!s.server_) {
    *error = start_error;
    return nullptr;
  }
  FoxgloveServer& web = *s.server_;

  for (size_t i = 0; i < s.options_.servers.size(); ++i) s.rigs_.push_back(s.MakeRig(i));
  web.SetSubscriptionListener([&s](uint32_t id, bool subscribed) { s.Route(id, subscribed); });

  // The page and its scripts, and Leaflet.
  web.AddHttpHandler("/", [](const HttpRequest& request) {
    const std::string path = request.path == "/" ? "/index.html" : request.path;
    const WebAsset* asset = FindWebAsset(path);
    if (asset == nullptr) return ErrorResponse(404, "NOT_FOUND", "no such page: " + request.path);
    HttpResponse r;
    r.content_type = std::string(asset->content_type);
    r.body = std::string(asset->body);
    r.headers.emplace_back("Cache-Control", "no-cache");
    return r;
  });
  web.AddHttpHandler("/leaflet/", [dir = s.options_.leaflet_dir](const HttpRequest& request) {
    return LeafletFile(dir, request.path.substr(std::string("/leaflet/").size()));
  });
  web.AddHttpHandler("/api/", [&s](const HttpRequest& request) { return s.Api(request); });
  for (auto& rig : s.rigs_) rig->link->Start();
  return station;
}

namespace {

HttpResponse MethodNotAllowed(const HttpRequest& request) {
  return ErrorResponse(405, "METHOD_NOT_ALLOWED",
                       request.method + " is not allowed on " + request.path);
}

// GET: the active config. POST: a partial config merged by the server, with the operator's token.
HttpResponse ConfigCall(RigLink& rig, const HttpRequest& request) {
  v1::PipelineConfig config;
  if (request.method == "GET") {
    const grpc::Status status = rig.GetConfig(&config);
    return status.ok() ? JsonResponse(200, ProtoJson(config)) : RpcError(status);
  }
  if (request.method != "POST") return MethodNotAllowed(request);
  v1::PipelineConfig update;
  if (const auto parsed = pb::util::JsonStringToMessage(request.body, &update); !parsed.ok()) {
    return ErrorResponse(
        400, "INVALID_ARGUMENT",
        "the body is not a PipelineConfig in JSON: " + std::string(parsed.message()));
  }
  const grpc::Status status =
      rig.SetConfig(update, HeaderValue(request, "x-stevi-operator-token"), &config);
  return status.ok() ? JsonResponse(200, ProtoJson(config)) : RpcError(status);
}

// The server's latest snapshot as a PNG: ?kind=annotated (default), disparity or left.
HttpResponse SnapshotCall(RigLink& rig, const HttpRequest& request) {
  if (request.method != "GET") return MethodNotAllowed(request);
  std::string kind = QueryValue(request.query, "kind");
  if (kind.empty()) kind = "annotated";
  if (kind != "annotated" && kind != "disparity" && kind != "left") {
    return ErrorResponse(400, "INVALID_ARGUMENT",
                         "kind: must be annotated, disparity or left (got '" + kind + "')");
  }
  v1::DisparitySnapshot snapshot;
  const grpc::Status status = rig.Snapshot(kind == "annotated", &snapshot);
  if (!status.ok()) return RpcError(status);
  HttpResponse r;
  r.content_type = "image/png";
  r.body = kind == "annotated"   ? snapshot.annotated_png()
           : kind == "disparity" ? snapshot.disparity_colour_png()
                                 : snapshot.left_png();
  r.headers.emplace_back("Content-Disposition", "inline; filename=\"" + rig.name() + "-" +
                                                    std::to_string(snapshot.frame_id()) + "-" +
                                                    kind + ".png\"");
  return r;
}

HttpResponse CalibrationsCall(RigLink& rig, const HttpRequest& request) {
  if (request.method != "GET") return MethodNotAllowed(request);
  v1::ListCalibrationsResponse list;
  const grpc::Status status = rig.ListCalibrations(&list);
  return status.ok() ? JsonResponse(200, ProtoJson(list)) : RpcError(status);
}

// POST {"id": "cal-000002"} with the operator's token.
HttpResponse ActivateCall(RigLink& rig, const HttpRequest& request) {
  if (request.method != "POST") return MethodNotAllowed(request);
  const nlohmann::json body = nlohmann::json::parse(request.body, nullptr, false);
  if (body.is_discarded() || !body.is_object() || !body.contains("id") || !body["id"].is_string()) {
    return ErrorResponse(400, "INVALID_ARGUMENT", "the body must be {\"id\": \"CALIBRATION_ID\"}");
  }
  v1::CalibrationRecord record;
  const grpc::Status status = rig.ActivateCalibration(
      body["id"].get<std::string>(), HeaderValue(request, "x-stevi-operator-token"), &record);
  return status.ok() ? JsonResponse(200, ProtoJson(record)) : RpcError(status);
}

// The georeferenced tracks seen so far, as `stevi export` writes them.
HttpResponse ExportCall(RigLink& rig, const HttpRequest& request, bool kml) {
  if (request.method != "GET") return MethodNotAllowed(request);
  const std::vector<client::TrackPoint> points = rig.TrackPoints();
  HttpResponse r;
  if (kml) {
    client::KmlOptions options;
    options.document_name = "stevi " + rig.name() + " tracks";
    r.content_type = "application/vnd.google-earth.kml+xml";
    r.body = client::ToKml(points, options);
  } else {
    r.content_type = "application/geo+json";
    r.body = client::ToGeoJson(points);
  }
  r.headers.emplace_back("Content-Disposition", "attachment; filename=\"" + rig.name() +
                                                    "-tracks." + (kml ? "kml" : "geojson") + "\"");
  return r;
}

}  // namespace

HttpResponse Station::Api(const HttpRequest& request) {
  if (request.path == "/api/site.geojson") {
    if (options_.site_geojson.empty()) {
      return ErrorResponse(404, "NOT_FOUND", "no site overlay (stevi station --site FILE)");
    }
    HttpResponse r;
    r.content_type = "application/geo+json";
    r.body = options_.site_geojson;
    return r;
  }
  if (request.path == "/api/rigs") {
    nlohmann::json rigs = nlohmann::json::array();
    for (const auto& rig : rigs_) {
      rigs.push_back({{"rig", rig->link->name()}, {"address", rig->link->address()}});
    }
    return JsonResponse(
        200, Dump(nlohmann::json{{"rigs", rigs}, {"site", !options_.site_geojson.empty()}}));
  }
  const std::optional<std::pair<std::string, std::string>> rig_path = SplitRigPath(request.path);
  if (!rig_path) return ErrorResponse(404, "NOT_FOUND", "no such API path: " + request.path);
  RigLink* rig = nullptr;
  for (const auto& r : rigs_) {
    if (r->link->name() == rig_path->first) rig = r->link.get();
  }
  if (rig == nullptr) return ErrorResponse(404, "NOT_FOUND", "no rig " + rig_path->first);
  const std::string& what = rig_path->second;
  if (what == "config") return ConfigCall(*rig, request);
  if (what == "snapshot") return SnapshotCall(*rig, request);
  if (what == "calibrations") return CalibrationsCall(*rig, request);
  if (what == "calibrations/activate") return ActivateCall(*rig, request);
  if (what == "export.geojson") return ExportCall(*rig, request, false);
  if (what == "export.kml") return ExportCall(*rig, request, true);
  return ErrorResponse(404, "NOT_FOUND", "no such API path: " + request.path);
}

}  // namespace stevi::station
