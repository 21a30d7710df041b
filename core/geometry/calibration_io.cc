#include "core/geometry/calibration_io.h"

#include "core/common/atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>

namespace stevi::geometry {
namespace {

constexpr double kRotationTolerance = 1e-3;

std::string ShapeText(int rows, int cols) {
  return std::to_string(rows) + "x" + std::to_string(cols);
}

bool AllFinite(const cv::Mat& m) { return m.empty() || cv::checkRange(m, true); }

template <int R, int C>
bool AllFinite(const cv::Matx<double, R, C>& m) {
  for (int i = 0; i < R * C; ++i) {
    if (!std::isfinite(m.val[i])) return false;
  }
  return true;
}

bool IsDistortionLength(int n) { return n == 4 || n == 5 || n == 8 || n == 12 || n == 14; }

// Problems of a rotation matrix, empty when it is one.
std::string RotationProblem(const cv::Matx33d& r) {
  const cv::Matx33d should_be_identity = r * r.t() - cv::Matx33d::eye();
  double worst = 0;
  for (double v : should_be_identity.val) worst = std::max(worst, std::abs(v));
  const double det = cv::determinant(r);
  if (worst > kRotationTolerance || std::abs(det - 1.0) > kRotationTolerance) {
    std::ostringstream s;
    s << "not a rotation (max |R R^T - I| = " << worst << ", det = " << det << ")";
    return s.str();
  }
  return {};
}

// The node at `key`, or an empty node (OpenCV may throw on malformed input).
cv::FileNode Lookup(const cv::FileNode& root, const std::string& key) {
  try {
    return root[key];
  } catch (const cv::Exception&) {
    return cv::FileNode();
  }
}

// Key `key`'s node as a plain list of numbers, row-major, for the first of `shapes` with that many
// elements; nullopt (with a problem appended) when it is not one.
std::optional<cv::Mat> ReadNumberList(const cv::FileNode& node, const std::string& key,
                                      const std::vector<cv::Size>& shapes,
                                      const std::string& expected,
                                      std::vector<std::string>& problems) {
  std::vector<double> values;
  for (const cv::FileNode& element : node) {
    if (!element.isInt() && !element.isReal()) {
      problems.push_back(key + ": expected " + expected + ", got a list with a non-number");
      return std::nullopt;
    }
    values.push_back(static_cast<double>(element));
  }
  for (const cv::Size& s : shapes) {
    if (static_cast<int>(values.size()) == s.area()) {
      return cv::Mat(values, true).reshape(1, s.height);
    }
  }
  problems.push_back(key + ": expected " + expected + ", got a list of " +
                     std::to_string(values.size()) + " numbers");
  return std::nullopt;
}

// Key `key`'s node as an !!opencv-matrix of one of `shapes`; nullopt (with a problem appended) when
// it is not one. OpenCV allocates rows x cols (whatever it makes of them) before it compares the
// data's length with them, so a file announcing a huge matrix would allocate gigabytes: only a map
// announcing an accepted shape is handed over.
std::optional<cv::Mat> ReadOpenCvMatrix(const cv::FileNode& node, const std::string& key,
                                        const std::vector<cv::Size>& shapes,
                                        const std::string& expected,
                                        std::vector<std::string>& problems) {
  const cv::FileNode rows = Lookup(node, "rows");
  const cv::FileNode cols = Lookup(node, "cols");
  if (!rows.isInt() || !cols.isInt()) {
    problems.push_back(key + ": expected " + expected +
                       " (an !!opencv-matrix with rows, cols, dt and data, or a list of numbers)");
    return std::nullopt;
  }
  const int r = static_cast<int>(rows);
  const int c = static_cast<int>(cols);
  const bool accepted = std::any_of(shapes.begin(), shapes.end(), [&](const cv::Size& s) {
    return s.height == r && s.width == c;
  });
  if (!accepted) {
    problems.push_back(key + ": expected " + expected + ", got " + ShapeText(r, c));
    return std::nullopt;
  }
  cv::Mat m;
  try {
    node >> m;
  } catch (const cv::Exception&) {
    m = cv::Mat();
  }
  if (m.empty()) {
    problems.push_back(key + ": expected " + expected +
                       " (an !!opencv-matrix with rows, cols, dt and data, or a list of numbers)");
    return std::nullopt;
  }
  return m;
}

// Reads one key as a matrix; nullopt (with a problem appended) when missing or malformed.
// `shapes` lists the accepted (rows, cols) pairs; `expected` describes them for the message.
std::optional<cv::Mat> ReadMatrix(const cv::FileNode& root, const std::string& key, bool required,
                                  const std::vector<cv::Size>& shapes, const std::string& expected,
                                  std::vector<std::string>& problems) {
  const cv::FileNode node = Lookup(root, key);
  if (node.empty() || node.isNone()) {
    if (required) problems.push_back(key + ": missing (expected " + expected + ")");
    return std::nullopt;
  }
  std::optional<cv::Mat> read;
  if (node.isSeq()) {
    read = ReadNumberList(node, key, shapes, expected, problems);
  } else if (node.isMap()) {
    read = ReadOpenCvMatrix(node, key, shapes, expected, problems);
  } else {
    problems.push_back(key + ": expected " + expected + ", got a single value");
    return std::nullopt;
  }
  if (!read) return std::nullopt;
  const cv::Mat& m = *read;
  if (m.channels() != 1) {
    problems.push_back(key + ": expected " + expected + ", got " + std::to_string(m.channels()) +
                       " channels");
    return std::nullopt;
  }
  bool shape_ok = false;
  for (const cv::Size& s : shapes) {
    if (m.rows == s.height && m.cols == s.width) shape_ok = true;
  }
  if (!shape_ok) {
    problems.push_back(key + ": expected " + expected + ", got " + ShapeText(m.rows, m.cols));
    return std::nullopt;
  }
  cv::Mat m64;
  m.convertTo(m64, CV_64F);
  if (!AllFinite(m64)) {
    problems.push_back(key + ": has non-finite values");
    return std::nullopt;
  }
  return m64;
}

std::optional<int> ReadPositiveInt(const cv::FileNode& root, const std::string& key,
                                   std::vector<std::string>& problems) {
  const cv::FileNode node = Lookup(root, key);
  if (node.empty() || node.isNone()) {
    problems.push_back(key + ": missing (expected a positive integer)");
    return std::nullopt;
  }
  if (!node.isInt()) {
    problems.push_back(key + ": expected a positive integer");
    return std::nullopt;
  }
  const int v = static_cast<int>(node);
  if (v <= 0) {
    problems.push_back(key + ": expected a positive integer, got " + std::to_string(v));
    return std::nullopt;
  }
  return v;
}

template <int R, int C>
cv::Matx<double, R, C> ToMatx(const cv::Mat& m) {
  cv::Matx<double, R, C> out;
  for (int r = 0; r < R; ++r) {
    for (int c = 0; c < C; ++c) out(r, c) = m.at<double>(r, c);
  }
  return out;
}

Result<StereoCalibration> ParseStorage(const cv::FileStorage& fs) {
  std::vector<std::string> problems;
  const cv::FileNode root = fs.root();
  if (!root.empty() && !root.isNone() && !root.isMap()) {
    return InvalidArgument(
        "expected a map of calibration keys (image_width, M1, ...) at the top level");
  }
  StereoCalibration c;

  const std::optional<int> width = ReadPositiveInt(root, "image_width", problems);
  const std::optional<int> height = ReadPositiveInt(root, "image_height", problems);
  if (width && height) c.image_size = cv::Size(*width, *height);

  const std::vector<cv::Size> k3x3 = {cv::Size(3, 3)};
  const std::vector<cv::Size> k3x4 = {cv::Size(4, 3)};
  const std::vector<cv::Size> k4x4 = {cv::Size(4, 4)};
  const std::vector<cv::Size> k_vec3 = {cv::Size(1, 3), cv::Size(3, 1)};
  std::vector<cv::Size> k_dist;
  for (int n : {4, 5, 8, 12, 14}) {
    k_dist.emplace_back(n, 1);
    k_dist.emplace_back(1, n);
  }
  const std::string dist_text = "a 1xN or Nx1 matrix with N in {4, 5, 8, 12, 14}";

  if (auto m = ReadMatrix(root, "M1", true, k3x3, "a 3x3 matrix", problems))
    c.M1 = ToMatx<3, 3>(*m);
  if (auto m = ReadMatrix(root, "D1", true, k_dist, dist_text, problems))
    c.D1 = m->reshape(1, 1).clone();
  if (auto m = ReadMatrix(root, "M2", true, k3x3, "a 3x3 matrix", problems))
    c.M2 = ToMatx<3, 3>(*m);
  if (auto m = ReadMatrix(root, "D2", true, k_dist, dist_text, problems))
    c.D2 = m->reshape(1, 1).clone();
  if (auto m = ReadMatrix(root, "R", true, k3x3, "a 3x3 matrix", problems)) c.R = ToMatx<3, 3>(*m);
  if (auto m = ReadMatrix(root, "T", true, k_vec3, "a 3x1 or 1x3 matrix", problems)) {
    const cv::Mat t = m->reshape(1, 3);
    c.T = cv::Vec3d(t.at<double>(0), t.at<double>(1), t.at<double>(2));
  }
  if (auto m = ReadMatrix(root, "R1", false, k3x3, "a 3x3 matrix", problems))
    c.R1 = ToMatx<3, 3>(*m);
  if (auto m = ReadMatrix(root, "R2", false, k3x3, "a 3x3 matrix", problems))
    c.R2 = ToMatx<3, 3>(*m);
  if (auto m = ReadMatrix(root, "P1", false, k3x4, "a 3x4 matrix", problems))
    c.P1 = ToMatx<3, 4>(*m);
  if (auto m = ReadMatrix(root, "P2", false, k3x4, "a 3x4 matrix", problems))
    c.P2 = ToMatx<3, 4>(*m);
  if (auto m = ReadMatrix(root, "Q", false, k4x4, "a 4x4 matrix", problems)) c.Q = ToMatx<4, 4>(*m);
  if (auto m = ReadMatrix(root, "E", false, k3x3, "a 3x3 matrix", problems)) c.E = ToMatx<3, 3>(*m);
  if (auto m = ReadMatrix(root, "F", false, k3x3, "a 3x3 matrix", problems)) c.F = ToMatx<3, 3>(*m);

  // Only check the values once every key could be read, so a missing key is not reported twice.
  if (problems.empty()) problems = c.Validate();
  if (!problems.empty()) return InvalidArgument(problems);
  return c;
}

Error WithPrefix(Error e, const std::string& prefix) {
  e.message = prefix + e.message;
  return e;
}

// A readable reason from an OpenCV exception. OpenCV's YAML parser puts "(line): message" in
// `func` and the parser function's name in `err`. `line_offset` undoes lines we prepended.
std::string OpenCvReason(const cv::Exception& e, int line_offset = 0) {
  if (e.code == cv::Error::StsParseError && e.func.size() > 2 && e.func[0] == '(') {
    const std::size_t close = e.func.find("): ");
    if (close != std::string::npos) {
      const std::string line_text = e.func.substr(1, close - 1);
      const std::string message = e.func.substr(close + 3);
      char* end = nullptr;
      const long line = std::strtol(line_text.c_str(), &end, 10);
      if (end != line_text.c_str() && *end == '\0') {
        return "line " + std::to_string(std::max(1L, line - line_offset)) + ": " + message;
      }
      return message;
    }
  }
  return e.err.empty() ? std::string(e.what()) : e.err;
}

}  // namespace

std::vector<std::string> StereoCalibration::Validate() const {
  std::vector<std::string> problems;
  if (image_size.width <= 0 || image_size.height <= 0) {
    problems.push_back("image_width, image_height: must be > 0 (got " +
                       ShapeText(image_size.width, image_size.height) + ")");
  }
  auto check_camera = [&](const std::string& name, const cv::Matx33d& m) {
    if (!AllFinite(m)) {
      problems.push_back(name + ": has non-finite values");
      return;
    }
    if (!(m(0, 0) > 0) || !(m(1, 1) > 0)) {
      problems.push_back(name + ": focal lengths fx, fy must be > 0 (got " +
                         std::to_string(m(0, 0)) + ", " + std::to_string(m(1, 1)) + ")");
    }
    if (m(2, 0) != 0 || m(2, 1) != 0 || std::abs(m(2, 2) - 1.0) > 1e-9) {
      problems.push_back(name + ": last row must be (0 0 1)");
    }
  };
  auto check_distortion = [&](const std::string& name, const cv::Mat& d) {
    if (d.empty() || d.rows != 1 || d.type() != CV_64FC1 || !IsDistortionLength(d.cols)) {
      problems.push_back(name + ": expected a 1xN CV_64F row with N in {4, 5, 8, 12, 14}, got " +
                         (d.empty() ? std::string("nothing") : ShapeText(d.rows, d.cols)));
      return;
    }
    if (!AllFinite(d)) problems.push_back(name + ": has non-finite values");
  };
  auto check_rotation = [&](const std::string& name, const cv::Matx33d& r) {
    if (!AllFinite(r)) {
      problems.push_back(name + ": has non-finite values");
      return;
    }
    if (std::string p = RotationProblem(r); !p.empty()) problems.push_back(name + ": " + p);
  };
  check_camera("M1", M1);
  check_distortion("D1", D1);
  check_camera("M2", M2);
  check_distortion("D2", D2);
  check_rotation("R", R);
  if (!AllFinite(cv::Matx31d(T.val))) {
    problems.push_back("T: has non-finite values");
  } else if (!(cv::norm(T) > 0)) {
    problems.push_back("T: the baseline |T| must be > 0");
  }

  const int rectification_terms =
      R1.has_value() + R2.has_value() + P1.has_value() + P2.has_value() + Q.has_value();
  if (rectification_terms != 0 && rectification_terms != 5) {
    problems.push_back("R1, R2, P1, P2, Q: give all five rectification terms or none (got " +
                       std::to_string(rectification_terms) + ")");
  }
  if (R1) check_rotation("R1", *R1);
  if (R2) check_rotation("R2", *R2);
  auto check_projection = [&](const std::string& name, const cv::Matx34d& p) {
    if (!AllFinite(p)) {
      problems.push_back(name + ": has non-finite values");
    } else if (!(p(0, 0) > 0) || !(p(1, 1) > 0)) {
      problems.push_back(name + ": focal lengths must be > 0");
    }
  };
  if (P1) check_projection("P1", *P1);
  if (P2) check_projection("P2", *P2);
  if (Q && !AllFinite(*Q)) problems.push_back("Q: has non-finite values");
  if (E && !AllFinite(*E)) problems.push_back("E: has non-finite values");
  if (F && !AllFinite(*F)) problems.push_back("F: has non-finite values");
  return problems;
}

std::string YamlTextProblem(std::string_view text) {
  std::size_t root_indent = std::string_view::npos;  // of the first line with content
  std::size_t number = 1;
  for (std::size_t start = 0; start < text.size(); ++number) {
    std::size_t end = text.find('\n', start);
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(start, end - start);
    start = end + 1;
    const std::size_t indent = std::min(line.find_first_not_of(' '), line.size());
    line.remove_prefix(indent);
    const std::string at = "line " + std::to_string(number) + ": ";
    if (line.empty() || line[0] == '\r' || line[0] == '#') continue;
    if (line[0] == ':') return at + "an empty key (the line starts with ':')";
    if (line.substr(0, 3) == "...") {
      return at + "'...' (the end of a YAML document) is not supported";
    }
    if (root_indent == std::string_view::npos) {
      if (line[0] == '%') continue;  // a directive
      if (line.substr(0, 3) == "---") {
        line.remove_prefix(3);
        const std::size_t after = line.find_first_not_of(' ');
        if (after == std::string_view::npos || line[after] == '\r' || line[after] == '#') continue;
        return at + "content on the '---' line (start it on the next line)";
      }
      if (line[0] == '{' || line[0] == '[') {
        return at + "expected a map at the top level, as 'key: value' lines (not '" +
               std::string(1, line[0]) + "')";
      }
      root_indent = indent;
    } else if (indent < root_indent) {
      return at + "indented less than the first line (" + std::to_string(indent) + " < " +
             std::to_string(root_indent) + " spaces): the top level must be one map";
    }
  }
  return {};
}

Result<StereoCalibration> LoadCalibrationYaml(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    return NotFound("calibration file not found: " + path);
  }
  if (std::filesystem::is_directory(path, ec)) {
    return InvalidArgument(path + ": is a directory, not a calibration file");
  }
  {
    std::ifstream in(path, std::ios::binary);
    const std::string text{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
    if (std::string problem = YamlTextProblem(text); !problem.empty()) {
      return InvalidArgument(path + ": not a valid calibration YAML file (" + problem + ")");
    }
  }
  cv::FileStorage fs;
  try {
    if (!fs.open(path, cv::FileStorage::READ | cv::FileStorage::FORMAT_YAML)) {
      return InvalidArgument(path + ": cannot open the calibration file");
    }
  } catch (const cv::Exception& e) {
    return InvalidArgument(path + ": not a valid calibration YAML file (" + OpenCvReason(e) + ")");
  } catch (const std::exception& e) {
    return InvalidArgument(path + ": not a valid calibration YAML file (" + e.what() + ")");
  }
  Result<StereoCalibration> result = ParseStorage(fs);
  if (!result.ok()) return WithPrefix(result.error(), path + ": ");
  return result;
}

Result<StereoCalibration> ParseCalibrationYaml(const std::string& yaml_text) {
  if (std::string problem = YamlTextProblem(yaml_text); !problem.empty()) {
    return InvalidArgument("calibration YAML: not valid YAML (" + problem + ")");
  }
  cv::FileStorage fs;
  int header_lines = 0;
  try {
    // OpenCV detects the format from the text; a YAML document may omit the %YAML header.
    std::string text = yaml_text;
    if (text.rfind("%YAML", 0) != 0) {
      text = "%YAML:1.0\n---\n" + text;
      header_lines = 2;
    }
    if (!fs.open(text,
                 cv::FileStorage::READ | cv::FileStorage::MEMORY | cv::FileStorage::FORMAT_YAML)) {
      return InvalidArgument("calibration YAML: cannot parse the text");
    }
  } catch (const cv::Exception& e) {
    return InvalidArgument("calibration YAML: not valid YAML (" + OpenCvReason(e, header_lines) +
                           ")");
  } catch (const std::exception& e) {
    return InvalidArgument(std::string("calibration YAML: not valid YAML (") + e.what() + ")");
  }
  return ParseStorage(fs);
}

Result<std::string> CalibrationYamlText(const StereoCalibration& calibration) {
  if (std::vector<std::string> problems = calibration.Validate(); !problems.empty()) {
    return WithPrefix(InvalidArgument(problems), "refusing to write an invalid calibration: ");
  }
  try {
    cv::FileStorage fs(
        ".yaml", cv::FileStorage::WRITE | cv::FileStorage::MEMORY | cv::FileStorage::FORMAT_YAML);
    fs << "image_width" << calibration.image_size.width;
    fs << "image_height" << calibration.image_size.height;
    fs << "M1" << cv::Mat(calibration.M1);
    fs << "D1" << calibration.D1;
    fs << "M2" << cv::Mat(calibration.M2);
    fs << "D2" << calibration.D2;
    fs << "R" << cv::Mat(calibration.R);
    fs << "T" << cv::Mat(calibration.T);
    if (calibration.R1) fs << "R1" << cv::Mat(*calibration.R1);
    if (calibration.R2) fs << "R2" << cv::Mat(*calibration.R2);
    if (calibration.P1) fs << "P1" << cv::Mat(*calibration.P1);
    if (calibration.P2) fs << "P2" << cv::Mat(*calibration.P2);
    if (calibration.Q) fs << "Q" << cv::Mat(*calibration.Q);
    if (calibration.E) fs << "E" << cv::Mat(*calibration.E);
    if (calibration.F) fs << "F" << cv::Mat(*calibration.F);
    return fs.releaseAndGetString();
  } catch (const cv::Exception& e) {
    return Internal("could not format the calibration (" + OpenCvReason(e) + ")");
  }
}

Status SaveCalibrationYaml(const StereoCalibration& calibration, const std::string& path) {
  Result<std::string> text = CalibrationYamlText(calibration);
  if (!text.ok()) return WithPrefix(text.error(), path + ": ");
  return AtomicWriteFile(path, *text);
}

StereoCalibration IdealCalibration(cv::Size image_size, double f_px, double baseline_m, double cx,
                                   double cy) {
  StereoCalibration c;
  c.image_size = image_size;
  c.M1 = cv::Matx33d(f_px, 0, cx, 0, f_px, cy, 0, 0, 1);
  c.M2 = c.M1;
  c.D1 = cv::Mat::zeros(1, 5, CV_64F);
  c.D2 = cv::Mat::zeros(1, 5, CV_64F);
  c.R = cv::Matx33d::eye();
  c.T = cv::Vec3d(-baseline_m, 0, 0);
  // The rectification terms cv::stereoRectify gives for this rig (CALIB_ZERO_DISPARITY).
  c.R1 = cv::Matx33d::eye();
  c.R2 = cv::Matx33d::eye();
  c.P1 = cv::Matx34d(f_px, 0, cx, 0, 0, f_px, cy, 0, 0, 0, 1, 0);
  c.P2 = cv::Matx34d(f_px, 0, cx, -f_px * baseline_m, 0, f_px, cy, 0, 0, 0, 1, 0);
  // Q(3,2) = -1/T'x = 1/B, and Q(3,3) = (cx - cx')/T'x = 0.
  c.Q = cv::Matx44d(1, 0, 0, -cx, 0, 1, 0, -cy, 0, 0, 0, f_px, 0, 0, 1.0 / baseline_m, 0);
  // E = [T]x R with R = I, F = M2^-T E M1^-1.
  const cv::Vec3d& t = c.T;
  c.E = cv::Matx33d(0, -t[2], t[1], t[2], 0, -t[0], -t[1], t[0], 0);
  const cv::Matx33d k_inv = c.M1.inv();
  c.F = k_inv.t() * (*c.E) * k_inv;
  return c;
}

}  // namespace stevi::geometry
