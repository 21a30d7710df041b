#include "drivers/files/image_source.h"

#include "core/common/format.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

namespace stevi::drivers {
namespace {

bool IsPattern(const std::string& path) { return path.find('%') != std::string::npos; }

// A pattern is untrusted input: before it goes near snprintf it must hold exactly one integer
// conversion %[flags][width]d or %[flags][width]i (flags from "0-+ ", width up to 2 digits);
// "%%" is a literal '%'.
// Returns the problem, or nullopt when the pattern is safe.
std::optional<std::string> CheckPattern(const std::string& pattern) {
  int conversions = 0;
  for (size_t i = 0; i < pattern.size(); ++i) {
    if (pattern[i] != '%') continue;
    ++i;
    if (i < pattern.size() && pattern[i] == '%') continue;  // literal '%'
    while (i < pattern.size() &&
           (pattern[i] == '0' || pattern[i] == '-' || pattern[i] == '+' || pattern[i] == ' ')) {
      ++i;
    }
    int width_digits = 0;
    while (i < pattern.size() && pattern[i] >= '0' && pattern[i] <= '9') {
      ++i;
      ++width_digits;
    }
    if (width_digits > 2) return "the field width is too large";
    if (i >= pattern.size()) return "ends inside a conversion";
    const char c = pattern[i];
    if (c != 'd' && c != 'i') {
      return std::string("has the conversion '%") + c +
             "'; only one integer conversion such as %d or %04d is allowed";
    }
    ++conversions;
  }
  if (conversions != 1) {
    return "must have exactly one integer conversion such as %d or %04d (it has " +
           std::to_string(conversions) + ")";
  }
  return std::nullopt;
}

std::string Format(const std::string& pattern, int index) {
  // Safe: CheckPattern() accepted the pattern (one int conversion, bounded width).
  const int n = std::snprintf(nullptr, 0, pattern.c_str(), index);
  std::string out(static_cast<size_t>(n) + 1, '\0');
  std::snprintf(out.data(), out.size(), pattern.c_str(), index);
  out.resize(static_cast<size_t>(n));
  return out;
}

// Reads an 8-bit grey, BGR or BGRA image (BGRA becomes BGR). Errors name the file.
Result<cv::Mat> ReadImage(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    return NotFound(path + ": no such file");
  }
  cv::Mat image = cv::imread(path, cv::IMREAD_UNCHANGED);
  if (image.empty()) return InvalidArgument(path + ": cannot decode the image");
  if (image.depth() != CV_8U) {
    return InvalidArgument(path + ": " + (image.depth() == CV_16U ? "16-bit" : "non-8-bit") +
                           " images are not supported (type " + cv::typeToString(image.type()) +
                           "); convert to 8-bit grey or colour");
  }
  switch (image.channels()) {
    case 1:
    case 3: return image;
    case 4: {
      cv::Mat bgr;
      cv::cvtColor(image, bgr, cv::COLOR_BGRA2BGR);
      return bgr;
    }
    default:
      return InvalidArgument(path + ": images with " + std::to_string(image.channels()) +
                             " channels are not supported (want grey, BGR or BGRA)");
  }
}

Status CheckPair(const cv::Mat& left, const std::string& left_name, const cv::Mat& right,
                 const std::string& right_name, const cv::Size& want) {
  if (left.size() != right.size()) {
    return InvalidArgument(left_name + " is " + SizeText(left.size()) + " but " + right_name +
                           " is " + SizeText(right.size()) + ": the pair must have one size");
  }
  if (left.size() != want) {
    return InvalidArgument(left_name + " is " + SizeText(left.size()) +
                           " but the calibration's image size is " + SizeText(want));
  }
  return Status::Ok();
}

class ImageSource : public StereoSource {
 public:
  ImageSource(ImageSourceOptions options, std::shared_ptr<const geometry::StereoRig> rig)
      : options_(std::move(options)), rig_(std::move(rig)) {}

  std::string Describe() const override {
    return std::string(video_ ? "video " : "images ") + options_.left + " " + options_.right +
           " (" + SizeText(rig_->image_size()) + ")";
  }
  std::shared_ptr<const geometry::StereoRig> Rig() const override { return rig_; }
  double NominalFps() const override { return options_.fps; }

  // Opens the source and checks its first pair (kept for the first Next()).
  Status Open() {
    video_ = !IsPattern(options_.left);
    next_index_ = video_ ? 0 : options_.first_index;
    if (video_) {
      if (Status s = OpenVideos(); !s) return s;
    }
    Result<StereoFrame> first = ReadPair(next_index_);
    if (!first.ok()) return first.error();
    pending_ = std::move(first.value());
    return Status::Ok();
  }

  Result<StereoFrame> Next() override {
    if (pending_) {
      StereoFrame frame = std::move(*pending_);
      pending_.reset();
      return Finish(std::move(frame));
    }
    Result<StereoFrame> frame = ReadPair(next_index_);
    if (!frame.ok() && frame.error().code == ErrorCode::kOutOfRange && options_.loop) {
      // Wrap around: the sequence time keeps increasing over laps.
      const int64_t first = video_ ? 0 : options_.first_index;
      if (next_index_ == first) return frame.error();  // nothing to loop over
      lap_length_ = next_index_ - first;
      ++laps_;
      if (video_) {
        if (Status s = OpenVideos(); !s) return s.error();
      }
      next_index_ = first;
      frame = ReadPair(next_index_);
    }
    if (!frame.ok()) return frame.error();
    return Finish(std::move(frame.value()));
  }

 private:
  Status OpenVideos() {
    left_video_.release();
    right_video_.release();
    for (const std::string* path : {&options_.left, &options_.right}) {
      std::error_code ec;
      if (!std::filesystem::exists(*path, ec)) {
        return NotFound(*path + ": no such file");
      }
    }
    if (!left_video_.open(options_.left))
      return InvalidArgument(options_.left + ": cannot open the video");
    if (!right_video_.open(options_.right)) {
      return InvalidArgument(options_.right + ": cannot open the video");
    }
    return Status::Ok();
  }

  // Reads the pair at `index` (pattern mode: the number substituted; video: the next frames).
  // kOutOfRange at the end of the sequence.
  Result<StereoFrame> ReadPair(int64_t index) {
    StereoFrame frame;
    std::string left_name, right_name;
    if (video_) {
      left_name = options_.left + " frame " + std::to_string(index);
      right_name = options_.right + " frame " + std::to_string(index);
      const bool got_left = left_video_.read(frame.left);
      const bool got_right = right_video_.read(frame.right);
      if (!got_left && !got_right) {
        return OutOfRange("end of the videos " + options_.left + " and " + options_.right +
                          " after " + std::to_string(index) + " frames");
      }
      if (!got_left || !got_right) {
        return InvalidArgument((got_left ? options_.right : options_.left) + " ended at frame " +
                               std::to_string(index) + " but " +
                               (got_left ? options_.left : options_.right) + " goes on");
      }
      for (cv::Mat* image : {&frame.left, &frame.right}) {
        if (image->depth() != CV_8U || (image->channels() != 1 && image->channels() != 3)) {
          return InvalidArgument((image == &frame.left ? left_name : right_name) +
                                 ": unsupported frame type " + cv::typeToString(image->type()));
        }
      }
    } else {
      left_name = Format(options_.left, static_cast<int>(index));
      right_name = Format(options_.right, static_cast<int>(index));
      std::error_code ec;
      const bool has_left = std::filesystem::exists(left_name, ec);
      const bool has_right = std::filesystem::exists(right_name, ec);
      if (!has_left && !has_right) {
        if (!opened_) {
          return NotFound(left_name + ": no such file (the sequence's first left image)");
        }
        return OutOfRange("end of the image sequence: neither " + left_name + " nor " + right_name +
                          " exists");
      }
      Result<cv::Mat> left = ReadImage(left_name);
      if (!left.ok()) return WithCode(left.error(), ErrorCode::kInvalidArgument);
      Result<cv::Mat> right = ReadImage(right_name);
      if (!right.ok()) return WithCode(right.error(), ErrorCode::kInvalidArgument);
      frame.left = std::move(left.value());
      frame.right = std::move(right.value());
    }
    if (Status s = CheckPair(frame.left, left_name, frame.right, right_name, rig_->image_size());
        !s) {
      return s.error();
    }
    frame.index = index;
    opened_ = true;
    return frame;
  }

  // A missing file in the middle of the sequence is a broken pair, not a missing source.
  Error WithCode(Error error, ErrorCode code) const {
    if (opened_) error.code = code;
    return error;
  }

  StereoFrame Finish(StereoFrame frame) {
    const int64_t sequence_index = frame.index + laps_ * lap_length_;
    frame.t_ns = static_cast<int64_t>(
        std::llround(static_cast<double>(sequence_index) * 1e9 / options_.fps));
    frame.unix_time_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                             std::chrono::system_clock::now().time_since_epoch())
                             .count();
    frame.rectified = !rig_->needs_remap();
    next_index_ = frame.index + 1;
    return frame;
  }

  ImageSourceOptions options_;
  std::shared_ptr<const geometry::StereoRig> rig_;
  bool video_ = false;
  bool opened_ = false;  // a first pair was read
  cv::VideoCapture left_video_, right_video_;
  std::optional<StereoFrame> pending_;
  int64_t next_index_ = 0;
  int64_t laps_ = 0;
  int64_t lap_length_ = 0;
};

}  // namespace

std::vector<std::string> ImageSourceOptions::Validate() const {
  std::vector<std::string> problems;
  if (left.empty()) problems.push_back("left: must not be empty");
  if (right.empty()) problems.push_back("right: must not be empty");
  if (calibration.empty())
    problems.push_back("calibration: must not be empty (a calibration YAML)");
  if (!(fps > 0) || !std::isfinite(fps)) {
    char buf[64];
    std::snprintf(buf, sizeof(buf), "%g", fps);
    problems.push_back(std::string("fps: must be > 0 (got ") + buf + ")");
  }
  if (first_index < 0) {
    problems.push_back("first_index: must be >= 0 (got " + std::to_string(first_index) + ")");
  }
  if (!left.empty() && !right.empty()) {
    const bool left_pattern = IsPattern(left);
    const bool right_pattern = IsPattern(right);
    if (left_pattern != right_pattern) {
      problems.push_back("right: must be a pattern like left ('" + left + "' vs '" + right +
                         "'): use two patterns or two videos");
    }
    if (left_pattern) {
      if (auto p = CheckPattern(left)) problems.push_back("left: pattern '" + left + "' " + *p);
    }
    if (right_pattern) {
      if (auto p = CheckPattern(right)) problems.push_back("right: pattern '" + right + "' " + *p);
    }
  }
  return problems;
}

Result<std::unique_ptr<StereoSource>> OpenImageSource(const ImageSourceOptions& options) {
  if (std::vector<std::string> problems = options.Validate(); !problems.empty()) {
    return InvalidArgument(problems);
  }
  Result<geometry::StereoRig> rig = geometry::StereoRig::FromFile(options.calibration);
  if (!rig.ok()) return rig.error();
  auto source = std::make_unique<ImageSource>(
      options, std::make_shared<const geometry::StereoRig>(std::move(rig.value())));
  if (Status s = source->Open(); !s) return s.error();
  return std::unique_ptr<StereoSource>(std::move(source));
}

}  // namespace stevi::drivers
