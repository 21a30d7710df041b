#include "drivers/recording/recording_reader.h"

#include "core/common/format.h"

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <iterator>
#include <utility>
#include <vector>

#include <google/protobuf/util/json_util.h>
#include <opencv2/imgcodecs.hpp>

#include "core/geometry/calibration_io.h"

namespace stevi::drivers {
namespace {

namespace fs = std::filesystem;

bool MatEqual(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type()) return false;
  return a.empty() || cv::norm(a, b, cv::NORM_INF) == 0;
}

template <typename T>
bool OptionalEqual(const std::optional<T>& a, const std::optional<T>& b) {
  if (a.has_value() != b.has_value()) return false;
  return !a.has_value() || *a == *b;
}

bool CalibrationsIdentical(const geometry::StereoCalibration& a,
                           const geometry::StereoCalibration& b) {
  return a.image_size == b.image_size && a.M1 == b.M1 && a.M2 == b.M2 && MatEqual(a.D1, b.D1) &&
         MatEqual(a.D2, b.D2) && a.R == b.R && a.T == b.T && OptionalEqual(a.R1, b.R1) &&
         OptionalEqual(a.R2, b.R2) && OptionalEqual(a.E, b.E) && OptionalEqual(a.F, b.F) &&
         OptionalEqual(a.P1, b.P1) && OptionalEqual(a.P2, b.P2) && OptionalEqual(a.Q, b.Q);
}

// PNG's signature and the fields of its first chunk (IHDR), which libpng sizes its buffers by:
// checking them against the stored size first keeps a hostile file from asking for gigabytes.
constexpr unsigned char kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};

uint32_t BigEndian32(const unsigned char* p) {
  return (uint32_t{p[0]} << 24) | (uint32_t{p[1]} << 16) | (uint32_t{p[2]} << 8) | uint32_t{p[3]};
}

// The problem with an image's stored description or PNG header, empty when it is sound.
std::string ImageProblem(const v1::RecordedImage& image) {
  const int w = image.width(), h = image.height();
  if (w <= 0 || h <= 0 || w > kMaxImageSide || h > kMaxImageSide ||
      int64_t{w} * h > kMaxImagePixels) {
    return "size " + SizeText(w, h) + " is outside the format's limits";
  }
  if (image.channels() != 1 && image.channels() != 3) {
    return "has " + std::to_string(image.channels()) + " channels (1 or 3 expected)";
  }
  const std::string& data = image.data();
  const auto* bytes = reinterpret_cast<const unsigned char*>(data.data());
  if (data.size() < 33 || std::memcmp(bytes, kPngSignature, 8) != 0 ||
      std::memcmp(bytes + 12, "IHDR", 4) != 0) {
    return "is not a PNG";
  }
  const uint32_t png_w = BigEndian32(bytes + 16), png_h = BigEndian32(bytes + 20);
  const int bit_depth = bytes[24], colour_type = bytes[25];
  if (png_w != static_cast<uint32_t>(w) || png_h != static_cast<uint32_t>(h)) {
    return "PNG is " + std::to_string(png_w) + "x" + std::to_string(png_h) +
           " but the record says " + SizeText(w, h);
  }
  const int want_colour_type = image.channels() == 1 ? 0 : 2;  // grey, or RGB (decoded as BGR)
  if (bit_depth != 8 || colour_type != want_colour_type) {
    return "PNG has bit depth " + std::to_string(bit_depth) + " and colour type " +
           std::to_string(colour_type) + " (expected 8-bit " +
           (image.channels() == 1 ? "grey" : "colour") + ")";
  }
  return {};
}

void CheckFinite(const char* field, double value, bool positive,
                 std::vector<std::string>& problems) {
  if (!std::isfinite(value) || (positive && !(value > 0))) {
    std::string problem = field;
    problem += positive ? ": must be > 0 and finite" : ": must be finite";
    problem += Got(value);
    problems.push_back(std::move(problem));
  }
}

}  // namespace

std::string FormatBytes(uint64_t bytes) {
  if (bytes < 1024) return std::to_string(bytes) + " B";
  static constexpr const char* kUnits[] = {"KiB", "MiB", "GiB", "TiB", "PiB"};
  double value = static_cast<double>(bytes) / 1024.0;
  size_t unit = 0;
  while (value >= 1024.0 && unit + 1 < std::size(kUnits)) {
    value /= 1024.0;
    ++unit;
  }
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.1f %s", value, kUnits[unit]);
  return buf;
}

v1::VehicleState VehicleStateToProto(const geo::VehicleState& s) {
  v1::VehicleState p;
  p.set_unix_time_ns(s.t_ns);
  p.mutable_position()->set_lat_deg(s.lat_deg);
  p.mutable_position()->set_lon_deg(s.lon_deg);
  p.mutable_position()->set_alt_m(s.alt_m);
  p.set_roll_deg(s.roll_deg);
  p.set_pitch_deg(s.pitch_deg);
  p.set_yaw_deg(s.yaw_deg);
  p.mutable_velocity()->set_n_mps(s.velocity_ned_mps.x());
  p.mutable_velocity()->set_e_mps(s.velocity_ned_mps.y());
  p.mutable_velocity()->set_d_mps(s.velocity_ned_mps.z());
  p.set_position_sigma_horizontal_m(s.sigma.horizontal_m);
  p.set_position_sigma_vertical_m(s.sigma.vertical_m);
  p.set_tilt_sigma_deg(s.sigma.tilt_deg);
  p.set_yaw_sigma_deg(s.sigma.yaw_deg);
  return p;
}

geo::VehicleState VehicleStateFromProto(const v1::VehicleState& p) {
  geo::VehicleState s;
  s.t_ns = p.unix_time_ns();
  s.lat_deg = p.position().lat_deg();
  s.lon_deg = p.position().lon_deg();
  s.alt_m = p.position().alt_m();
  s.roll_deg = p.roll_deg();
  s.pitch_deg = p.pitch_deg();
  s.yaw_deg = p.yaw_deg();
  s.velocity_ned_mps =
      Eigen::Vector3d(p.velocity().n_mps(), p.velocity().e_mps(), p.velocity().d_mps());
  s.sigma.horizontal_m = p.position_sigma_horizontal_m();
  s.sigma.vertical_m = p.position_sigma_vertical_m();
  s.sigma.tilt_deg = p.tilt_sigma_deg();
  s.sigma.yaw_deg = p.yaw_sigma_deg();
  return s;
}

bool RigsIdentical(const geometry::StereoRig& a, const geometry::StereoRig& b) {
  return a.image_size() == b.image_size() && a.f_px() == b.f_px() &&
         a.baseline_m() == b.baseline_m() && a.cx() == b.cx() && a.cy() == b.cy() &&
         a.Q() == b.Q() && a.needs_remap() == b.needs_remap() &&
         a.calibration_id() == b.calibration_id() &&
         CalibrationsIdentical(a.calibration(), b.calibration());
}

Result<v1::RecordedRig> RecordedRigOf(const geometry::StereoRig& rig) {
  v1::RecordedRig recorded;
  recorded.set_image_width(rig.image_size().width);
  recorded.set_image_height(rig.image_size().height);
  recorded.set_calibration_id(rig.calibration_id());
  // OpenCV writes doubles with "%.16e" (17 significant digits), which strtod reads back to the
  // same bits: the YAML holds the calibration exactly.
  Result<std::string> yaml = geometry::CalibrationYamlText(rig.calibration());
  if (!yaml.ok()) {
    Error e = yaml.error();
    e.message = "rig: " + e.message;
    return e;
  }
  recorded.set_calibration_yaml(std::move(yaml.value()));

  // An ideal rig keeps f and B as given, where FromCalibration would derive B from P2 (to an ulp):
  // recognise it by rebuilding it.
  if (!rig.needs_remap()) {
    const geometry::StereoRig ideal = geometry::StereoRig::Ideal(
        rig.image_size(), rig.f_px(), rig.baseline_m(), rig.cx(), rig.cy(), rig.calibration_id());
    if (RigsIdentical(rig, ideal)) {
      v1::IdealRig* out = recorded.mutable_ideal();
      out->set_f_px(rig.f_px());
      out->set_baseline_m(rig.baseline_m());
      out->set_cx(rig.cx());
      out->set_cy(rig.cy());
      return recorded;
    }
  }
  Result<geometry::StereoRig> rebuilt = RigFromRecorded(recorded);
  if (!rebuilt.ok()) {
    return Internal("rig: cannot be rebuilt from its calibration YAML (" + rebuilt.error().message +
                    "), so a replay would not reproduce it");
  }
  if (!RigsIdentical(rig, *rebuilt)) {
    return Internal(
        "rig: the rig rebuilt from its calibration YAML differs from the original, so a "
        "replay would not reproduce it");
  }
  return recorded;
}

Result<geometry::StereoRig> RigFromRecorded(const v1::RecordedRig& recorded) {
  std::vector<std::string> problems;
  const int w = recorded.image_width(), h = recorded.image_height();
  // Also bounded in pixels, as the frames are: a rig that is not rectified builds remap tables
  // of 12 bytes per pixel when it opens (3 GiB and most of a minute for 16384x16384).
  if (w <= 0 || h <= 0 || w > kMaxImageSide || h > kMaxImageSide ||
      int64_t{w} * h > kMaxImagePixels) {
    problems.push_back("image_width, image_height: must be in [1, " +
                       std::to_string(kMaxImageSide) + "] and at most " +
                       std::to_string(kMaxImagePixels) + " pixels in all (got " + SizeText(w, h) +
                       ")");
  }
  if (recorded.has_ideal()) {
    const v1::IdealRig& ideal = recorded.ideal();
    CheckFinite("ideal.f_px", ideal.f_px(), true, problems);
    CheckFinite("ideal.baseline_m", ideal.baseline_m(), true, problems);
    CheckFinite("ideal.cx", ideal.cx(), false, problems);
    CheckFinite("ideal.cy", ideal.cy(), false, problems);
    if (!problems.empty()) return InvalidArgument(problems);
    return geometry::StereoRig::Ideal(cv::Size(w, h), ideal.f_px(), ideal.baseline_m(), ideal.cx(),
                                      ideal.cy(), recorded.calibration_id());
  }
  if (recorded.calibration_yaml().empty()) {
    problems.push_back("calibration_yaml: missing (and no ideal rig either)");
  }
  if (!problems.empty()) return InvalidArgument(problems);
  Result<geometry::StereoCalibration> calibration =
      geometry::ParseCalibrationYaml(recorded.calibration_yaml());
  if (!calibration.ok()) {
    Error e = calibration.error();
    e.message = "calibration_yaml: " + e.message;
    return e;
  }
  if (calibration->image_size != cv::Size(w, h)) {
    return InvalidArgument("calibration_yaml: image size " +
                           SizeText(calibration->image_size.width, calibration->image_size.height) +
                           " differs from image_width, image_height " + SizeText(w, h));
  }
  Result<geometry::StereoRig> rig =
      geometry::StereoRig::FromCalibration(*calibration, recorded.calibration_id());
  if (!rig.ok()) {
    Error e = rig.error();
    e.message = "calibration_yaml: " + e.message;
    return e;
  }
  return rig;
}

// ---- RecordingReader ----------------------------------------------------------------------------

Result<std::unique_ptr<RecordingReader>> RecordingReader::Open(const std::string& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) {
    return NotFound("recording " + dir + ": no such directory");
  }
  auto reader = std::unique_ptr<RecordingReader>(new RecordingReader());
  reader->dir_ = dir;
  const std::string manifest_path = (fs::path(dir) / kManifestFileName).string();
  reader->records_path_ = (fs::path(dir) / kRecordsFileName).string();

  // The manifest: bounded, then parsed by protobuf's JSON parser (unknown fields from a newer
  // writer are ignored; the version says whether we can read the records).
  if (!fs::exists(manifest_path, ec)) {
    return NotFound(manifest_path + ": not found (" + dir + " is not a recording directory)");
  }
  const uintmax_t manifest_size = fs::file_size(manifest_path, ec);
  if (ec) {
    return InvalidArgument(manifest_path + ": cannot read its size (" + ec.message() + ")");
  }
  if (manifest_size > kMaxManifestBytes) {
    return InvalidArgument(manifest_path + ": " + FormatBytes(manifest_size) + ", more than the " +
                           FormatBytes(kMaxManifestBytes) + " a manifest may have: not a manifest");
  }
  std::string text;
  {
    std::ifstream in(manifest_path, std::ios::binary);
    if (!in) {
      return InvalidArgument(manifest_path + ": cannot open it for reading");
    }
    text.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    if (in.bad()) return InvalidArgument(manifest_path + ": read failed");
  }
  google::protobuf::util::JsonParseOptions parse;
  parse.ignore_unknown_fields = true;
  const auto parsed = google::protobuf::util::JsonStringToMessage(text, &reader->manifest_, parse);
  if (!parsed.ok()) {
    return InvalidArgument(manifest_path + ": not a recording manifest (" +
                           std::string(parsed.message()) + ")");
  }
  const v1::RecordingManifest& m = reader->manifest_;
  if (m.format_version() == 0) {
    return InvalidArgument(manifest_path + ": format_version: missing (not a recording manifest)");
  }
  if (m.format_version() > kRecordingFormatVersion) {
    return InvalidArgument(
        manifest_path + ": format_version: " + std::to_string(m.format_version()) +
        " is newer than this program reads (" + std::to_string(kRecordingFormatVersion) + ")");
  }
  if (m.encoding() != v1::IMAGE_ENCODING_PNG) {
    return InvalidArgument(manifest_path + ": encoding: " + v1::ImageEncoding_Name(m.encoding()) +
                           " is not supported (IMAGE_ENCODING_PNG)");
  }
  if (!m.has_rig()) {
    return InvalidArgument(manifest_path + ": rig: missing");
  }
  Result<geometry::StereoRig> rig = RigFromRecorded(m.rig());
  if (!rig.ok()) {
    return InvalidArgument(manifest_path + ": rig: " + rig.error().message);
  }
  reader->rig_ = std::make_shared<const geometry::StereoRig>(std::move(rig.value()));

  if (!fs::exists(reader->records_path_, ec)) {
    return NotFound(reader->records_path_ + ": not found");
  }
  reader->file_size_ = fs::file_size(reader->records_path_, ec);
  if (ec) {
    return InvalidArgument(reader->records_path_ + ": cannot read its size (" + ec.message() + ")");
  }
  reader->records_.open(reader->records_path_, std::ios::binary);
  if (!reader->records_) {
    return InvalidArgument(reader->records_path_ + ": cannot open it for reading");
  }
  return reader;
}

Status RecordingReader::Rewind() {
  std::error_code ec;
  const uintmax_t size = fs::file_size(records_path_, ec);
  if (ec) {
    return InvalidArgument(records_path_ + ": cannot read its size (" + ec.message() + ")");
  }
  records_.clear();
  records_.seekg(0);
  if (!records_) return InvalidArgument(records_path_ + ": cannot seek");
  file_size_ = size;
  offset_ = 0;
  frames_read_ = 0;
  unknown_skipped_ = 0;
  ended_ = false;
  end_note_.clear();
  return Status::Ok();
}

std::nullopt_t RecordingReader::EndWith(const std::string& problem) {
  ended_ = true;
  end_note_ = records_path_ + ": " + problem;
  return std::nullopt;
}

Result<cv::Mat> RecordingReader::DecodeImage(const v1::RecordedImage& image,
                                             const char* side) const {
  cv::Mat decoded;
  try {
    const std::string& data = image.data();
    const cv::Mat bytes(1, static_cast<int>(data.size()), CV_8UC1, const_cast<char*>(data.data()));
    decoded = cv::imdecode(bytes, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    return InvalidArgument(std::string(side) + " image: " + e.what());
  }
  if (decoded.empty()) {
    return InvalidArgument(std::string(side) + " image: the PNG does not decode");
  }
  if (decoded.type() != CV_8UC(image.channels()) ||
      decoded.size() != cv::Size(image.width(), image.height())) {
    return InvalidArgument(
        std::string(side) + " image: decoded as " + cv::typeToString(decoded.type()) + " " +
        SizeText(decoded.cols, decoded.rows) + ", the record says " +
        std::to_string(image.channels()) + " channels " + SizeText(image.width(), image.height()));
  }
  return decoded;
}

std::optional<std::string> RecordingReader::ReadRecordBytes(uint64_t start,
                                                            const std::string& where) {
  // The varint32 length prefix of util::SerializeDelimitedToOstream: at most 5 bytes.
  uint64_t size = 0;
  int prefix_bytes = 0;
  while (true) {
    if (start + prefix_bytes >= file_size_) {
      return "truncated record" + where + " (the length prefix is cut)";
    }
    const int c = records_.get();
    if (c == std::char_traits<char>::eof()) {
      return "truncated record" + where + " (the file ended early)";
    }
    size |= static_cast<uint64_t>(c & 0x7f) << (7 * prefix_bytes);
    ++prefix_bytes;
    if ((c & 0x80) == 0) break;
    if (prefix_bytes == 5) return "corrupt record" + where + " (bad length prefix)";
  }
  // Bound the size before allocating anything for it.
  if (size > kMaxRecordBytes) {
    return "corrupt record" + where + " (it announces " + std::to_string(size) +
           " bytes, more than the " + FormatBytes(kMaxRecordBytes) + " limit)";
  }
  const uint64_t left = file_size_ - start - static_cast<uint64_t>(prefix_bytes);
  if (size > left) {
    return "truncated record" + where + " (" + std::to_string(size) + " bytes announced, " +
           std::to_string(left) + " left)";
  }
  buffer_.resize(size);
  records_.read(buffer_.data(), static_cast<std::streamsize>(size));
  if (static_cast<uint64_t>(records_.gcount()) != size) {
    return "truncated record" + where + " (the file ended early)";
  }
  offset_ = start + static_cast<uint64_t>(prefix_bytes) + size;
  return std::nullopt;
}

std::optional<std::string> RecordingReader::ReadFrame(const v1::RecordedFrame& f,
                                                      bool decode_images, const std::string& where,
                                                      StereoFrame& frame) const {
  if (!f.has_left() || !f.has_right()) {
    return "corrupt record" + where + " (a frame without both images)";
  }
  if (std::string problem = ImageProblem(f.left()); !problem.empty()) {
    return "corrupt record" + where + " (left image " + problem + ")";
  }
  if (std::string problem = ImageProblem(f.right()); !problem.empty()) {
    return "corrupt record" + where + " (right image " + problem + ")";
  }
  if (f.left().width() != f.right().width() || f.left().height() != f.right().height()) {
    return "corrupt record" + where + " (left and right differ in size)";
  }
  frame.index = f.index();
  frame.t_ns = f.t_ns();
  frame.unix_time_ns = f.unix_time_ns();
  frame.pair_skew_ns = f.pair_skew_ns();
  frame.rectified = f.rectified();
  if (decode_images) {
    Result<cv::Mat> left_image = DecodeImage(f.left(), "left");
    if (!left_image.ok()) {
      return "corrupt record" + where + " (" + left_image.error().message + ")";
    }
    Result<cv::Mat> right_image = DecodeImage(f.right(), "right");
    if (!right_image.ok()) {
      return "corrupt record" + where + " (" + right_image.error().message + ")";
    }
    frame.left = std::move(left_image.value());
    frame.right = std::move(right_image.value());
  }
  return std::nullopt;
}

std::optional<RecordingRecord> RecordingReader::Next(bool decode_images) {
  while (!ended_) {
    if (offset_ >= file_size_) {
      ended_ = true;
      return std::nullopt;
    }
    const uint64_t start = offset_;
    const std::string where =
        " after " + std::to_string(frames_read_) + " frames at byte " + std::to_string(start);
    if (std::optional<std::string> problem = ReadRecordBytes(start, where)) {
      return EndWith(*problem);
    }
    v1::RecordEntry entry;
    if (!entry.ParseFromString(buffer_)) {
      return EndWith("corrupt record" + where + " (not a RecordEntry)");
    }
    RecordingRecord record;
    record.offset = start;
    switch (entry.entry_case()) {
      case v1::RecordEntry::kFrame:
        if (std::optional<std::string> problem =
                ReadFrame(entry.frame(), decode_images, where, record.frame)) {
          return EndWith(*problem);
        }
        record.kind = RecordingRecord::Kind::kFrame;
        ++frames_read_;
        return record;
      case v1::RecordEntry::kVehicleState:
        record.kind = RecordingRecord::Kind::kVehicleState;
        record.vehicle_state = VehicleStateFromProto(entry.vehicle_state());
        return record;
      case v1::RecordEntry::kCalibration:
        record.kind = RecordingRecord::Kind::kCalibration;
        record.calibration.calibration_id = entry.calibration().calibration_id();
        record.calibration.yaml = entry.calibration().calibration_yaml();
        record.calibration.unix_time_ns = entry.calibration().unix_time_ns();
        return record;
      case v1::RecordEntry::ENTRY_NOT_SET:
        // A kind a newer writer added (its field is unknown to us): skip it, the framing holds.
        ++unknown_skipped_;
        break;
    }
  }
  return std::nullopt;
}

}  // namespace stevi::drivers
