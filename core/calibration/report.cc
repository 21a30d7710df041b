#include "core/calibration/report.h"

#include "core/common/format.h"
#include "core/geometry/calibration_io.h"

#include <concepts>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <iomanip>
#include <optional>
#include <sstream>
#include <type_traits>
#include <utility>

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
  std::vector<cv::FileNode> Seq(const cv::FileNode& parent, const std::string& key,
                                const std::string& where = "") {
    std::vector<cv::FileNode> out;
    const cv::FileNode node = Node(parent, key, where);
    if (node.empty() || node.isNone()) return out;
    if (!node.isSeq()) {
      problems_.push_back(where + key + ": expected a list");
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

// The YAML's field tables: each key once, in the file's order, with its member and its kind. The
// writer and the reader below are the two visitors of these tables. The keys are the file's own,
// not the protos' field names.
//   Number  a double                 Int   an int             Flag   a bool, written as 0 or 1
//   Text    a quoted string (WriteText, ReportText)           Choice a RejectReason by its name
//   Int64   a decimal string (FileStorage has no 64-bit integers)
//   Map     a nested map of its own table                     Texts  a list of strings
//   List    a list of maps, each element by its own table
template <class Self, class T>
concept Is = std::same_as<std::remove_const_t<Self>, T>;

template <Is<BoardSpec> Self, class V>
void YamlFields(Self& b, V& v) {
  v.Int("inner_cols", b.inner_cols);
  v.Int("inner_rows", b.inner_rows);
  v.Number("square_size_m", b.square_size_m);
}

template <Is<GateFailure> Self, class V>
void YamlFields(Self& f, V& v) {
  v.Text("gate", f.gate);
  v.Number("measured", f.measured);
  v.Number("limit", f.limit);
  v.Text("message", f.message);
}

template <Is<RejectedPair> Self, class V>
void YamlFields(Self& p, V& v) {
  v.Int("index", p.index);
  v.Text("name", p.name);
  v.Choice("reason", p.reason);
  v.Text("detail", p.detail);
}

template <Is<PairReport> Self, class V>
void YamlFields(Self& p, V& v) {
  v.Int("index", p.index);
  v.Text("name", p.name);
  v.Number("rms_left_px", p.rms_left_px);
  v.Number("rms_right_px", p.rms_right_px);
  v.Number("epipolar_mean_px", p.epipolar_mean_px);
  v.Number("coverage_left", p.coverage_left);
  v.Number("coverage_right", p.coverage_right);
}

template <Is<CalibrationReport> Self, class V>
void YamlFields(Self& r, V& v) {
  v.Int64("created_unix_ms", r.created_unix_ms);
  v.Flag("passed", r.passed);
  v.Flag("swap_left_right", r.swap_left_right);
  v.Int("image_width", r.image_size.width);
  v.Int("image_height", r.image_size.height);
  v.Map("board", r.board);
  v.Text("detector", r.detector);
  v.Int("pairs_given", r.pairs_given);
  v.Int("pairs_used", r.pairs_used);
  v.Number("rms_px", r.rms_px);
  v.Number("rms_left_px", r.rms_left_px);
  v.Number("rms_right_px", r.rms_right_px);
  v.Number("epipolar_mean_px", r.epipolar_mean_px);
  v.Number("epipolar_max_px", r.epipolar_max_px);
  v.Int("coverage_grid_cols", r.coverage_grid.width);
  v.Int("coverage_grid_rows", r.coverage_grid.height);
  v.Number("coverage_mean_view", r.coverage_mean_view);
  v.Number("coverage_min_view", r.coverage_min_view);
  v.Number("coverage_union_left", r.coverage_union_left);
  v.Number("coverage_union_right", r.coverage_union_right);
  v.Number("fx_left_px", r.fx_left_px);
  v.Number("fy_left_px", r.fy_left_px);
  v.Number("fx_right_px", r.fx_right_px);
  v.Number("fy_right_px", r.fy_right_px);
  v.Number("baseline_m", r.baseline_m);
  v.Number("rectified_f_px", r.rectified_f_px);
  v.List("failures", r.failures);
  v.Texts("warnings", r.warnings);
  v.List("rejected", r.rejected);
  v.List("pairs", r.pairs);
}

// Writes a table's fields into a FileStorage map.
class YamlWriter {
 public:
  explicit YamlWriter(cv::FileStorage& fs) : fs_(fs) {}

  void Number(const char* key, double value) { fs_ << key << value; }
  void Int(const char* key, int value) { fs_ << key << value; }
  void Flag(const char* key, bool value) { fs_ << key << static_cast<int>(value); }
  void Text(const char* key, const std::string& text) { WriteText(fs_, key, text); }
  void Int64(const char* key, std::int64_t value) { fs_ << key << std::to_string(value); }
  void Choice(const char* key, RejectReason reason) {
    fs_ << key << std::string(RejectReasonName(reason));
  }

  template <class T>
  void Map(const char* key, const T& value) {
    fs_ << key << "{";
    YamlFields(value, *this);
    fs_ << "}";
  }

  template <class T>
  void List(const char* key, const std::vector<T>& elements) {
    fs_ << key << "[";
    for (const T& element : elements) {
      fs_ << "{";
      YamlFields(element, *this);
      fs_ << "}";
    }
    fs_ << "]";
  }

  void Texts(const char* key, const std::vector<std::string>& texts) {
    fs_ << key << "[";
    for (const std::string& text : texts) WriteText(fs_, "", text);
    fs_ << "]";
  }

 private:
  cv::FileStorage& fs_;
};

// Reads a table's fields from the map `node`; each problem is named with `where` ("pairs[2].") in
// front of the key, and the field keeps its default.
class YamlReader {
 public:
  YamlReader(Reader& read, cv::FileNode node, std::string where)
      : read_(read), node_(std::move(node)), where_(std::move(where)) {}

  void Number(const char* key, double& value) { value = read_.Double(node_, key, where_); }
  void Int(const char* key, int& value) { value = read_.Int(node_, key, where_); }
  void Flag(const char* key, bool& value) { value = read_.Int(node_, key, where_) != 0; }
  void Text(const char* key, std::string& text) { text = read_.String(node_, key, where_); }

  void Int64(const char* key, std::int64_t& value) {
    const std::string text = read_.String(node_, key, where_);
    if (text.empty()) return;
    char* end = nullptr;
    value = std::strtoll(text.c_str(), &end, 10);
    if (*end != '\0') read_.Problem(where_ + key + ": expected a decimal integer");
  }

  void Choice(const char* key, RejectReason& reason) {
    const std::string name = read_.String(node_, key, where_);
    for (const RejectReason candidate : kAllReasons) {
      if (RejectReasonName(candidate) == name) {
        reason = candidate;
        return;
      }
    }
    read_.Problem(where_ + key + ": unknown value \"" + name + "\"");
  }

  template <class T>
  void Map(const char* key, T& value) {
    const cv::FileNode map = read_.Node(node_, key, where_);
    if (map.isMap()) {
      YamlReader fields(read_, map, where_ + key + ".");
      YamlFields(value, fields);
    } else if (!map.empty() && !map.isNone()) {
      read_.Problem(where_ + key + ": expected a map");
    }
  }

  template <class T>
  void List(const char* key, std::vector<T>& elements) {
    const std::vector<cv::FileNode> nodes = read_.Seq(node_, key, where_);
    for (std::size_t i = 0; i < nodes.size(); ++i) {
      YamlReader fields(read_, nodes[i], where_ + Where(key, i));
      YamlFields(elements.emplace_back(), fields);
    }
  }

  void Texts(const char* key, std::vector<std::string>& texts) {
    for (const cv::FileNode& node : read_.Seq(node_, key, where_)) {
      if (node.isString()) {
        texts.push_back(ReportText(static_cast<std::string>(node)));
      } else {
        read_.Problem(where_ + key + ": expected strings");
      }
    }
  }

 private:
  Reader& read_;
  cv::FileNode node_;
  std::string where_;
};

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
    YamlWriter writer(fs);
    YamlFields(r, writer);
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
    YamlReader fields(read, root, "");
    YamlFields(r, fields);
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
