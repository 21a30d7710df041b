#include "core/geometry/stereo_rig.h"

#include <cmath>
#include <filesystem>
#include <utility>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

namespace stevi::geometry {
namespace {

// Relative tolerance for "exactly" ideal values (identity R, zero distortion, equal cameras).
constexpr double kIdealTolerance = 1e-9;

bool Near(double a, double b, double scale) {
  return std::abs(a - b) <= kIdealTolerance * std::max(1.0, scale);
}

template <int R, int C>
bool MatxNear(const cv::Matx<double, R, C>& a, const cv::Matx<double, R, C>& b) {
  double scale = 0;
  for (int i = 0; i < R * C; ++i) scale = std::max({scale, std::abs(a.val[i]), std::abs(b.val[i])});
  for (int i = 0; i < R * C; ++i) {
    if (!Near(a.val[i], b.val[i], scale)) return false;
  }
  return true;
}

bool AllZero(const cv::Mat& m) { return m.empty() || cv::countNonZero(m != 0) == 0; }

// True when the raw images already are rectified: no distortion, identity R, T along x, equal
// square-pixel cameras, and rectification terms (when given) that do not ask for a remap.
bool IsAlreadyRectified(const StereoCalibration& c) {
  if (!AllZero(c.D1) || !AllZero(c.D2)) return false;
  if (!MatxNear(c.R, cv::Matx33d::eye())) return false;
  const double tx = std::abs(c.T[0]);
  if (!Near(c.T[1], 0, tx) || !Near(c.T[2], 0, tx)) return false;
  if (!MatxNear(c.M1, c.M2)) return false;
  if (!Near(c.M1(0, 0), c.M1(1, 1), c.M1(0, 0)) || c.M1(0, 1) != 0) return false;
  if (c.R1 && !MatxNear(*c.R1, cv::Matx33d::eye())) return false;
  if (c.R2 && !MatxNear(*c.R2, cv::Matx33d::eye())) return false;
  if (c.P1) {
    const cv::Matx34d& p = *c.P1;
    const cv::Matx33d k(p(0, 0), p(0, 1), p(0, 2), p(1, 0), p(1, 1), p(1, 2), p(2, 0), p(2, 1),
                        p(2, 2));
    if (!MatxNear(k, c.M1)) return false;
  }
  return true;
}

Status CheckImage(const cv::Mat& image, const char* name, cv::Size size) {
  const std::string who = std::string("Rectify: ") + name + ": ";
  if (image.empty()) return InvalidArgument(who + "empty image");
  if (image.type() != CV_8UC1 && image.type() != CV_8UC3) {
    return InvalidArgument(who + "expected 8-bit grey (CV_8UC1) or BGR (CV_8UC3), got " +
                           cv::typeToString(image.type()));
  }
  if (image.size() != size) {
    return InvalidArgument(who + "expected " + std::to_string(size.width) + "x" +
                           std::to_string(size.height) + " (the calibration's size), got " +
                           std::to_string(image.cols) + "x" + std::to_string(image.rows));
  }
  return Status::Ok();
}

// Grey copy of `in` into `out` (create semantics, so `out`'s buffer is reused).
void ToGrey(const cv::Mat& in, cv::Mat& out) {
  if (in.channels() == 3) {
    cv::cvtColor(in, out, cv::COLOR_BGR2GRAY);
  } else if (in.data != out.data) {
    in.copyTo(out);
  }
}

void Remap(const cv::Mat& raw, const cv::Mat& map1, const cv::Mat& map2, cv::Mat& scratch,
           cv::Mat& out) {
  const cv::Mat* grey = &raw;
  if (raw.channels() == 3) {
    cv::cvtColor(raw, scratch, cv::COLOR_BGR2GRAY);
    grey = &scratch;
  } else if (raw.data == out.data) {
    raw.copyTo(scratch);  // cv::remap cannot work in place.
    grey = &scratch;
  }
  cv::remap(*grey, out, map1, map2, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(0));
}

}  // namespace

Result<StereoRig> StereoRig::FromCalibration(const StereoCalibration& calibration,
                                             std::string calibration_id) {
  if (std::vector<std::string> problems = calibration.Validate(); !problems.empty()) {
    return InvalidArgument(problems);
  }
  if (calibration.T[0] > 0) {
    return InvalidArgument(
        "T: the camera named left sits to the right of the camera named right "
        "(T_x > 0); swap left and right");
  }
  if (std::abs(calibration.T[0]) <
      std::max(std::abs(calibration.T[1]), std::abs(calibration.T[2]))) {
    return InvalidArgument(
        "T: the baseline must be mostly horizontal (|T_x| largest); vertical or "
        "forward-looking rigs are not supported");
  }

  StereoRig rig;
  rig.calibration_ = calibration;
  rig.calibration_id_ = std::move(calibration_id);
  rig.image_size_ = calibration.image_size;
  StereoCalibration& c = rig.calibration_;

  if (IsAlreadyRectified(calibration)) {
    // Use the raw cameras as they are: the rectified geometry is exactly M1 and |T|.
    const StereoCalibration ideal =
        IdealCalibration(calibration.image_size, calibration.M1(0, 0), std::abs(calibration.T[0]),
                         calibration.M1(0, 2), calibration.M1(1, 2));
    c.R1 = ideal.R1;
    c.R2 = ideal.R2;
    c.P1 = ideal.P1;
    c.P2 = ideal.P2;
    c.Q = ideal.Q;
  } else {
    const bool given = c.R1 && c.R2 && c.P1 && c.P2 && c.Q;
    if (!given) {
      cv::Mat r1, r2, p1, p2, q;
      try {
        cv::stereoRectify(cv::Mat(c.M1), c.D1, cv::Mat(c.M2), c.D2, c.image_size, cv::Mat(c.R),
                          cv::Mat(c.T), r1, r2, p1, p2, q, cv::CALIB_ZERO_DISPARITY, 0.0);
      } catch (const cv::Exception& e) {
        return InvalidArgument(std::string("calibration: stereo rectification failed (") + e.err +
                               ")");
      }
      c.R1 = cv::Matx33d(r1);
      c.R2 = cv::Matx33d(r2);
      c.P1 = cv::Matx34d(p1);
      c.P2 = cv::Matx34d(p2);
      c.Q = cv::Matx44d(q);
    }
    if ((*c.P2)(1, 3) != 0 && std::abs((*c.P2)(1, 3)) > std::abs((*c.P2)(0, 3))) {
      return InvalidArgument(
          "P2: the rectification is vertical; only horizontal rigs are supported");
    }
    auto maps = std::make_shared<Maps>();
    try {
      cv::initUndistortRectifyMap(cv::Mat(c.M1), c.D1, cv::Mat(*c.R1), cv::Mat(*c.P1), c.image_size,
                                  CV_16SC2, maps->left_x, maps->left_y);
      cv::initUndistortRectifyMap(cv::Mat(c.M2), c.D2, cv::Mat(*c.R2), cv::Mat(*c.P2), c.image_size,
                                  CV_16SC2, maps->right_x, maps->right_y);
    } catch (const cv::Exception& e) {
      return InvalidArgument(std::string("calibration: building the remap tables failed (") +
                             e.err + ")");
    }
    rig.maps_ = std::move(maps);
  }

  const cv::Matx34d& p1 = *c.P1;
  const cv::Matx34d& p2 = *c.P2;
  rig.f_px_ = p1(0, 0);
  rig.cx_ = p1(0, 2);
  rig.cy_ = p1(1, 2);
  rig.baseline_m_ = std::abs(p2(0, 3) / p2(0, 0));
  rig.Q_ = *c.Q;
  if (!(rig.f_px_ > 0) || !(rig.baseline_m_ > 0) || !std::isfinite(rig.baseline_m_)) {
    return InvalidArgument("P1, P2: the rectified focal length and baseline must be > 0");
  }
  return rig;
}

Result<StereoRig> StereoRig::FromFile(const std::string& path) {
  Result<StereoCalibration> calibration = LoadCalibrationYaml(path);
  if (!calibration.ok()) return calibration.error();
  Result<StereoRig> rig =
      FromCalibration(*calibration, std::filesystem::path(path).stem().string());
  if (!rig.ok()) {
    Error e = rig.error();
    e.message = path + ": " + e.message;
    return e;
  }
  return rig;
}

StereoRig StereoRig::Ideal(cv::Size image_size, double f_px, double baseline_m, double cx,
                           double cy, std::string calibration_id) {
  StereoRig rig;
  rig.calibration_ = IdealCalibration(image_size, f_px, baseline_m, cx, cy);
  rig.calibration_id_ = std::move(calibration_id);
  rig.image_size_ = image_size;
  rig.f_px_ = f_px;
  rig.baseline_m_ = baseline_m;
  rig.cx_ = cx;
  rig.cy_ = cy;
  rig.Q_ = *rig.calibration_.Q;
  return rig;
}

StereoRig StereoRig::Binned(int factor) const {
  const double k = factor;
  const double shift = (k - 1) / 2;
  return Ideal(cv::Size(image_size_.width / factor, image_size_.height / factor), f_px_ / k,
               baseline_m_, (cx_ - shift) / k, (cy_ - shift) / k, calibration_id_);
}

int BinningFactor(int width, int max_width, double floor_px) {
  if (max_width <= 0 || width <= max_width) return 1;
  int factor = (width + max_width - 1) / max_width;
  if (floor_px > 0) {
    while (factor > 1 && floor_px / factor < kMinBinnedDisparityPx) --factor;
  }
  return factor;
}

void BinImage(const cv::Mat& in, int factor, cv::Mat& out) {
  if (factor <= 1) {
    in.copyTo(out);
    return;
  }
  const cv::Size binned(in.cols / factor, in.rows / factor);
  // Whole blocks only, so that cv::resize averages exactly factor x factor pixels per output pixel.
  const cv::Mat whole = in(cv::Rect(0, 0, binned.width * factor, binned.height * factor));
  cv::resize(whole, out, binned, 0, 0, cv::INTER_AREA);
}

Status StereoRig::Rectify(const cv::Mat& raw_left, const cv::Mat& raw_right, cv::Mat& rect_left,
                          cv::Mat& rect_right) const {
  if (Status s = CheckImage(raw_left, "left image", image_size_); !s) return s;
  if (Status s = CheckImage(raw_right, "right image", image_size_); !s) return s;
  if (!maps_) {
    ToGrey(raw_left, rect_left);
    ToGrey(raw_right, rect_right);
    return Status::Ok();
  }
  // Per-thread scratch for the grey conversion of colour input: the rig itself stays immutable.
  thread_local cv::Mat scratch;
  Remap(raw_left, maps_->left_x, maps_->left_y, scratch, rect_left);
  Remap(raw_right, maps_->right_x, maps_->right_y, scratch, rect_right);
  return Status::Ok();
}

}  // namespace stevi::geometry
