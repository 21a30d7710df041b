#include "core/calibration/report.h"

#include "core/common/format.h"
#include "core/geometry/calibration_io.h"

#include <cstdio>
#include <cstdlib>
#include <iomanip>
#include <optional>
#include <sstream>

namespace stevi::calibration {
namespace {

constexpr RejectReason kAllReasons[] = {
    RejectReason::kUndecodable, RejectReason::kTooLarge,    RejectReason::kSizeMismatch,
    RejectReason::kSizeDiffers, RejectReason::kNoBoardLeft, RejectReason::kNoBoardRight,
    RejectReason::kNoBoard,     RejectReason::kOutlier,
};

std::string Percent(double fraction) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.0f %%", 100.0 * fraction);
  return buf;
}

// A report's text as the YAML carries it: OpenCV's parser refuses quoted strings of 4096 bytes or
// more and mangles its numeric escapes, so the text is cut to kMaxReportText bytes (at a UTF-8
// character boundary) and control characters other than newline, return and tab become '?'.
// Applied when writing and when reading, so a report reads back as it was written.
constexpr std::size_t kMaxReportText = 1024;

std::string ReportText(const std::string& text) {
  std::size_t end = text.size();
  if (end > kMaxReportText) {
    end = kMaxReportText;
    while (end > 0 && (static_cast<unsigned char>(text[end]) & 0xC0) == 0x80) --end;
  }
  std::string out = text.substr(0, end);
  for (char& c : out) {
    if (static_cast<unsigned char>(c) < 0x20 && c != '\n' && c != '\r' && c != '\t') c = '?';
  }
  return out;
}

// Writes a string value (`key` empty inside a list) double-quoted, with the escapes OpenCV's
// parser reads back. FileStorage's own `fs << text` takes a text starting with '[', '{', ']' or
// '}' for a structure, drops a backslash before one, and writes a text framed by quotes, or ending
// in spaces, unquoted, so that it reads back different (or not at all).
void WriteText(cv::FileStorage& fs, const std::string& key, const std::string& text) {
  std::string quoted = "\"";
  for (const char c : ReportText(text)) {
    switch (c) {
      case '"':
      case '\\':
        quoted += '\\';
        quoted += c;
        break;
      case '\n': quoted += "\\n"; break;
      case '\r': quoted += "\\r"; break;
      case '\t': quoted += "\\t"; break;
      default: quoted += c;
    }
  }
  quoted += '"';
  cv::write(fs, key, quoted);  // a text framed by '"' is written as it is
}

// Readers that append "key: problem" and return a default on failure. OpenCV may throw on
// malformed nodes, so every access is guarded.
class Reader {
 public:
  explicit Reader(std::vector<std::string>& problems) : problems_(problems) {}

  cv::FileNode Node(const cv::FileNode& parent, const std::string& key, const std::string& where) {
    try {
      cv::FileNode node = parent[key];
      if (node.empty() || node.isNone()) problems_.push_back(where + key + ": missing");
      return node;
    } catch (const cv::Exception&) {
      problems_.push_back(where + key + ": unreadable");
      return cv::FileNode();
    }
  }

  double Double(const cv::FileNode& parent, const std::string& key, const std::string& where = "") {
    const cv::FileNode node = Node(parent, key, where);
    if (node.empty() || node.isNone()) return 0;
    if (!node.isReal() && !node.isInt()) {
      problems_.push_back(where + key + ": expected a number");
      return 0;
    }
    return static_cast<double>(node);
  }

  int Int(const cv::FileNode& parent, const std::string& key, const std::string& where = "") {
    const cv::FileNode node = Node(parent, key, where);
    if (node.empty() || node.isNone()) return 0;
    if (!node.isInt()) {
      problems_.push_back(where + key + ": expected an integer");
      return 0;
    }
    return static_cast<int>(node);
  }

  std::string String(const cv::FileNode& parent, const std::string& key,
                     const std::string& where = "") {
    const cv::FileNode node = Node(parent, key, where);
    if (node.empty() || node.isNone()) return {};
    if (!node.isString()) {
      problems_.push_back(where + key + ": expected a string");
      return {};
    }
    return ReportText(static_cast<std::string>(node));
  }

  // A sequence (possibly empty); problems when it is something else.
  std::vector<cv::FileNode> Seq(const cv::FileNode& parent, const std::string& key) {
    std::vector<cv::FileNode> out;
    const cv::FileNode node = Node(parent, key, "");
    if (node.empty() || node.isNone()) return out;
    if (!node.isSeq()) {
      problems_.push_back(key + ": expected a list");
      return out;
    }
    for (const cv::FileNode& element : node) out.push_back(element);
    return out;
  }

  // Appends a problem of its own ("board: expected a map").
  void Problem(const std::string& problem) { problems_.push_back(problem); }

 private:
  std::vector<std::string>& problems_;
};

std::string Where(const std::string& list, std::size_t i) {
  return list + "[" + std::to_string(i) + "].";
}

}  // namespace

std::string_view RejectReasonName(RejectReason reason) {
  switch (reason) {
    case RejectReason::kUndecodable: return "undecodable";
    case RejectReason::kTooLarge: return "too_large";
    case RejectReason::kSizeMismatch: return "size_mismatch";
    case RejectReason::kSizeDiffers: return "size_differs";
    case RejectReason::kNoBoardLeft: return "no_board_left";
    case RejectReason::kNoBoardRight: return "no_board_right";
    case RejectReason::kNoBoard: return "no_board";
    case RejectReason::kOutlier: return "outlier";
  }
  return "unknown";
}

std::string FormatReportText(const CalibrationReport& r) {
  std::ostringstream s;
  s << "Stereo calibration: " << (r.passed ? "PASSED" : "FAILED");
  if (!r.passed) {
    s << " (";
    for (std::size_t i = 0; i < r.failures.size(); ++i) s << (i ? ", " : "") << r.failures[i].gate;
    s << ")";
  }
  s << "\n";
  s << "  image " << r.image_size.width << "x" << r.image_size.height << ", board of "
    << r.board.Name() << " inner corners, squares of " << Fixed(r.board.square_size_m * 1000, 1)
    << " mm, detector " << r.detector << "\n";
  s << "  pairs: " << r.pairs_used << " used of " << r.pairs_given << " given, "
    << r.rejected.size() << " rejected\n";
  s << "  RMS reprojection error: " << Fixed(r.rms_px, 3) << " px (left " << Fixed(r.rms_left_px, 3)
    << " px, right " << Fixed(r.rms_right_px, 3) << " px)\n";
  s << "  epipolar error after rectification: mean " << Fixed(r.epipolar_mean_px, 3) << " px, max "
    << Fixed(r.epipolar_max_px, 3) << " px\n";
  s << "  board coverage: per view mean " << Percent(r.coverage_mean_view) << ", min "
    << Percent(r.coverage_min_view) << "; union of the views on a " << r.coverage_grid.width << "x"
    << r.coverage_grid.height << " grid: left " << Percent(r.coverage_union_left) << ", right "
    << Percent(r.coverage_union_right) << "\n";
  s << "  focal length: left " << Fixed(r.fx_left_px, 2) << " x " << Fixed(r.fy_left_px, 2)
    << " px, right " << Fixed(r.fx_right_px, 2) << " x " << Fixed(r.fy_right_px, 2)
    << " px; rectified " << Fixed(r.rectified_f_px, 2) << " px\n";
  s << "  baseline: " << Fixed(r.baseline_m * 1000, 2) << " mm\n";
  if (r.swap_left_right) {
    s << "  LEFT AND RIGHT SWAPPED: the camera named left is on the right; camera 1 of this "
         "calibration is the input's right camera, so the source's images must be swapped\n";
  }
  if (!r.failures.empty()) {
    s << "Failed gates:\n";
    for (const GateFailure& f : r.failures) s << "  - " << f.message << "\n";
  }
  if (!r.warnings.empty()) {
    s << "Warnings:\n";
    for (const std::string& w : r.warnings) s << "  - " << w << "\n";
  }
  if (!r.rejected.empty()) {
    s << "Rejected pairs:\n";
    for (const RejectedPair& p : r.rejected) {
      s << "  - #" << p.index << (p.name.empty() ? "" : " " + p.name) << ": "
        << RejectReasonName(p.reason) << ": " << p.detail << "\n";
    }
  }
  if (!r.pairs.empty()) {
    s << "Pairs used (rms and coverage of camera 1 / camera 2, epipolar error):\n";
    for (const PairReport& p : r.pairs) {
      s << "  #" << std::setw(3) << std::left << p.index << std::right << " " << std::setw(16)
        << std::left << p.name << std::right << " rms " << Fixed(p.rms_left_px, 3) << " / "
        << Fixed(p.rms_right_px, 3) << " px, epipolar " << Fixed(p.epipolar_mean_px, 3)
        << " px, coverage " << Percent(p.coverage_left) << " / " << Percent(p.coverage_right)
        << "\n";
    }
  }
  return s.str();
}

Result<std::string> ReportToYaml(const CalibrationReport& r) {
  try {
    cv::FileStorage fs(
        ".yaml", cv::FileStorage::WRITE | cv::FileStorage::MEMORY | cv::FileStorage::FORMAT_YAML);
    // FileStorage has no 64-bit integers: the time is written as a decimal string.
    fs << "created_unix_ms" << std::to_string(r.created_unix_ms);
    fs << "passed" << static_cast<int>(r.passed);
    fs << "swap_left_right" << static_cast<int>(r.swap_left_right);
    fs << "image_width" << r.image_size.width;
    fs << "image_height" << r.image_size.height;
    fs << "board"
       << "{"
       << "inner_cols" << r.board.inner_cols << "inner_rows" << r.board.inner_rows
       << "square_size_m" << r.board.square_size_m << "}";
    WriteText(fs, "detector", r.detector);
    fs << "pairs_given" << r.pairs_given;
    fs << "pairs_used" << r.pairs_used;
    fs << "rms_px" << r.rms_px;
    fs << "rms_left_px" << r.rms_left_px;
    fs << "rms_right_px" << r.rms_right_px;
    fs << "epipolar_mean_px" << r.epipolar_mean_px;
    fs << "epipolar_max_px" << r.epipolar_max_px;
    fs << "coverage_grid_cols" << r.coverage_grid.width;
    fs << "coverage_grid_rows" << r.coverage_grid.height;
    fs << "coverage_mean_view" << r.coverage_mean_view;
    fs << "coverage_min_view" << r.coverage_min_view;
    fs << "coverage_union_left" << r.coverage_union_left;
    fs << "coverage_union_right" << r.coverage_union_right;
    fs << "fx_left_px" << r.fx_left_px;
    fs << "fy_left_px" << r.fy_left_px;
    fs << "fx_right_px" << r.fx_right_px;
    fs << "fy_right_px" << r.fy_right_px;
    fs << "baseline_m" << r.baseline_m;
    fs << "rectified_f_px" << r.rectified_f_px;
    fs << "failures"
       << "[";
    for (const GateFailure& f : r.failures) {
      fs << "{";
      WriteText(fs, "gate", f.gate);
      fs << "measured" << f.measured << "limit" << f.limit;
      WriteText(fs, "message", f.message);
      fs << "}";
    }
    fs << "]";
    fs << "warnings"
       << "[";
    for (const std::string& w : r.warnings) WriteText(fs, "", w);
    fs << "]";
    fs << "rejected"
       << "[";
    for (const RejectedPair& p : r.rejected) {
      fs << "{"
         << "index" << p.index;
      WriteText(fs, "name", p.name);
      fs << "reason" << std::string(RejectReasonName(p.reason));
      WriteText(fs, "detail", p.detail);
      fs << "}";
    }
    fs << "]";
    fs << "pairs"
       << "[";
    for (const PairReport& p : r.pairs) {
      fs << "{"
         << "index" << p.index;
      WriteText(fs, "name", p.name);
      fs << "rms_left_px" << p.rms_left_px << "rms_right_px" << p.rms_right_px << "epipolar_mean_px"
         << p.epipolar_mean_px << "coverage_left" << p.coverage_left << "coverage_right"
         << p.coverage_right << "}";
    }
    fs << "]";
    return fs.releaseAndGetString();
  } catch (const cv::Exception& e) {
    return Internal("cannot format the calibration report (" + e.err + ")");
  }
}

namespace {

// Opens the YAML text for reading ("%YAML:1.0" is put in front of a text without it).
std::optional<Error> OpenYaml(const std::string& yaml_text, cv::FileStorage& fs) {
  if (std::string problem = geometry::YamlTextProblem(yaml_text); !problem.empty()) {
    return InvalidArgument("calibration report: not valid YAML (" + problem + ")");
  }
  try {
    std::string text = yaml_text;
    if (text.rfind("%YAML", 0) != 0) text = "%YAML:1.0\n---\n" + text;
    if (!fs.open(text,
                 cv::FileStorage::READ | cv::FileStorage::MEMORY | cv::FileStorage::FORMAT_YAML)) {
      return InvalidArgument("calibration report: cannot parse the text");
    }
  } catch (const cv::Exception& e) {
    return InvalidArgument("calibration report: not valid YAML (" + e.err + ")");
  } catch (const std::exception& e) {
    return InvalidArgument(std::string("calibration report: not valid YAML (") + e.what() + ")");
  }
  return std::nullopt;
}

// The single values: time, verdict, image, board, detector, pair counts and the figures.
void ReadFigures(Reader& read, const cv::FileNode& root, CalibrationReport& r) {
  const std::string created = read.String(root, "created_unix_ms");
  if (!created.empty()) {
    char* end = nullptr;
    r.created_unix_ms = std::strtoll(created.c_str(), &end, 10);
    if (*end != '\0') read.Problem("created_unix_ms: expected a decimal integer");
  }
  r.passed = read.Int(root, "passed") != 0;
  r.swap_left_right = read.Int(root, "swap_left_right") != 0;
  r.image_size = cv::Size(read.Int(root, "image_width"), read.Int(root, "image_height"));
  const cv::FileNode board = read.Node(root, "board", "");
  if (board.isMap()) {
    r.board.inner_cols = read.Int(board, "inner_cols", "board.");
    r.board.inner_rows = read.Int(board, "inner_rows", "board.");
    r.board.square_size_m = read.Double(board, "square_size_m", "board.");
  } else if (!board.empty() && !board.isNone()) {
    read.Problem("board: expected a map");
  }
  r.detector = read.String(root, "detector");
  r.pairs_given = read.Int(root, "pairs_given");
  r.pairs_used = read.Int(root, "pairs_used");
  r.rms_px = read.Double(root, "rms_px");
  r.rms_left_px = read.Double(root, "rms_left_px");
  r.rms_right_px = read.Double(root, "rms_right_px");
  r.epipolar_mean_px = read.Double(root, "epipolar_mean_px");
  r.epipolar_max_px = read.Double(root, "epipolar_max_px");
  r.coverage_grid =
      cv::Size(read.Int(root, "coverage_grid_cols"), read.Int(root, "coverage_grid_rows"));
  r.coverage_mean_view = read.Double(root, "coverage_mean_view");
  r.coverage_min_view = read.Double(root, "coverage_min_view");
  r.coverage_union_left = read.Double(root, "coverage_union_left");
  r.coverage_union_right = read.Double(root, "coverage_union_right");
  r.fx_left_px = read.Double(root, "fx_left_px");
  r.fy_left_px = read.Double(root, "fy_left_px");
  r.fx_right_px = read.Double(root, "fx_right_px");
  r.fy_right_px = read.Double(root, "fy_right_px");
  r.baseline_m = read.Double(root, "baseline_m");
  r.rectified_f_px = read.Double(root, "rectified_f_px");
}

// Each element of the list `key`, read by read_one(read, element, "key[i].").
template <typename T, typename ReadOne>
std::vector<T> ReadList(Reader& read, const cv::FileNode& root, const std::string& key,
                        ReadOne read_one) {
  std::vector<T> out;
  const std::vector<cv::FileNode> elements = read.Seq(root, key);
  for (std::size_t i = 0; i < elements.size(); ++i) {
    out.push_back(read_one(read, elements[i], Where(key, i)));
  }
  return out;
}

GateFailure ReadFailure(Reader& read, const cv::FileNode& node, const std::string& where) {
  GateFailure f;
  f.gate = read.String(node, "gate", where);
  f.measured = read.Double(node, "measured", where);
  f.limit = read.Double(node, "limit", where);
  f.message = read.String(node, "message", where);
  return f;
}

std::vector<std::string> ReadWarnings(Reader& read, const cv::FileNode& root) {
  std::vector<std::string> out;
  const cv::FileNode warnings = read.Node(root, "warnings", "");
  if (warnings.isSeq()) {
    for (const cv::FileNode& w : warnings) {
      if (w.isString()) {
        out.push_back(ReportText(static_cast<std::string>(w)));
      } else {
        read.Problem("warnings: expected strings");
      }
    }
  } else if (!warnings.empty() && !warnings.isNone()) {
    read.Problem("warnings: expected a list");
  }
  return out;
}

RejectedPair ReadRejectedPair(Reader& read, const cv::FileNode& node, const std::string& where) {
  RejectedPair p;
  p.index = read.Int(node, "index", where);
  p.name = read.String(node, "name", where);
  const std::string reason = read.String(node, "reason", where);
  bool known = false;
  for (RejectReason candidate : kAllReasons) {
    if (RejectReasonName(candidate) == reason) {
      p.reason = candidate;
      known = true;
    }
  }
  if (!known) read.Problem(where + "reason: unknown value \"" + reason + "\"");
  p.detail = read.String(node, "detail", where);
  return p;
}

PairReport ReadPairReport(Reader& read, const cv::FileNode& node, const std::string& where) {
  PairReport p;
  p.index = read.Int(node, "index", where);
  p.name = read.String(node, "name", where);
  p.rms_left_px = read.Double(node, "rms_left_px", where);
  p.rms_right_px = read.Double(node, "rms_right_px", where);
  p.epipolar_mean_px = read.Double(node, "epipolar_mean_px", where);
  p.coverage_left = read.Double(node, "coverage_left", where);
  p.coverage_right = read.Double(node, "coverage_right", where);
  return p;
}

}  // namespace

Result<CalibrationReport> ParseReportYaml(const std::string& yaml_text) {
  cv::FileStorage fs;
  if (std::optional<Error> error = OpenYaml(yaml_text, fs)) return *error;
  std::vector<std::string> problems;
  CalibrationReport r;
  try {
    const cv::FileNode root = fs.root();
    if (!root.isMap()) {
      return InvalidArgument("calibration report: expected a map at the top level");
    }
    Reader read(problems);
    ReadFigures(read, root, r);
    r.failures = ReadList<GateFailure>(read, root, "failures", ReadFailure);
    r.warnings = ReadWarnings(read, root);
    r.rejected = ReadList<RejectedPair>(read, root, "rejected", ReadRejectedPair);
    r.pairs = ReadList<PairReport>(read, root, "pairs", ReadPairReport);
    if (static_cast<int>(r.pairs.size()) != r.pairs_used && problems.empty()) {
      problems.push_back("pairs_used: " + std::to_string(r.pairs_used) + " but " +
                         std::to_string(r.pairs.size()) + " pairs are listed");
    }
  } catch (const cv::Exception& e) {
    problems.push_back("unreadable (" + e.err + ")");
  } catch (const std::exception& e) {
    problems.push_back(std::string("unreadable (") + e.what() + ")");
  }
  if (!problems.empty()) {
    Error e = InvalidArgument(problems);
    e.message = "calibration report: " + e.message;
    return e;
  }
  return r;
}

}  // namespace stevi::calibration
