// stevi calibrate --board COLSxROWS --square-mm MM [--apply] [--json] [gates] (--left PATTERN
// --right PATTERN | --capture N [--interval S]): stereo calibration from chessboard pairs,
// uploaded or grabbed by the server.
#include <cctype>
#include <cstdint>
#include <cstdio>
#include <iomanip>
#include <iostream>
#include <string>
#include <utility>
#include <vector>

#include "client/cli/commands.h"
#include "core/common/flags.h"

namespace stevi::client::commands {
namespace {

// Inner corners of the board per side.
constexpr flags::WholeRange kBoardCorners{.lo = 2, .hi = 100};

struct CalibrateArgs {
  v1::CalibrationSettings settings;
  std::string left_pattern, right_pattern;
  int capture = 0;
  double interval_s = 0.5;
  bool apply = false, json = false, have_board = false, have_square = false;
};

// The board's size, "9x6", into the settings; "" or the usage problem.
std::string TakeBoard(const std::string& text, CalibrateArgs& a) {
  const auto board = flags::ParseNumberPair(text, 'x', kBoardCorners);
  if (!board.ok()) {
    return flags::Expected("calibrate", "--board",
                           "COLSxROWS inner corners (" + std::to_string(kBoardCorners.lo) + ".." +
                               std::to_string(kBoardCorners.hi) + ")",
                           text);
  }
  a.settings.mutable_board()->set_columns(static_cast<int32_t>(board.value.first));
  a.settings.mutable_board()->set_rows(static_cast<int32_t>(board.value.second));
  a.have_board = true;
  return "";
}

std::string ParseArgs(const Args& args, CalibrateArgs& a) {
  v1::CalibrationSettings& s = a.settings;
  const std::string problem =
      flags::FlagSet("calibrate")
          .Switch("--apply", &a.apply)
          .Switch("--json", &a.json)
          .Value("--board", [&a](const std::string& text) { return TakeBoard(text, a); })
          .Real("--square-mm", {.lo = 0.1, .hi = 10000, .unit = "millimetres"},
                [&a](double mm) {
                  a.settings.mutable_board()->set_square_m(mm / 1000.0);
                  a.have_square = true;
                })
          .Text("--left", &a.left_pattern)
          .Text("--right", &a.right_pattern)
          .Whole("--capture", {.lo = 1, .hi = 200, .what = "a whole number of pairs"},
                 [&a](std::int64_t n) { a.capture = static_cast<int>(n); })
          .Real("--interval", {.lo = 0, .hi = 60, .unit = "seconds"},
                [&a](double seconds) { a.interval_s = seconds; })
          .Whole(
              "--min-pairs", {.lo = 1, .hi = 1000},
              [&s](std::int64_t n) { s.mutable_gates()->set_min_pairs(static_cast<int32_t>(n)); })
          .Real("--max-rms", {.lo = 0, .hi = 100, .unit = "pixels"},
                [&s](double px) { s.mutable_gates()->set_max_rms_px(px); })
          .Real("--max-epipolar", {.lo = 0, .hi = 100, .unit = "pixels"},
                [&s](double px) { s.mutable_gates()->set_max_epipolar_px(px); })
          .Real("--alpha", {.lo = 0, .hi = 1, .unit = "a number"},
                [&s](double alpha) { s.set_alpha(alpha); })
          .Parse(args);
  if (a.apply) s.set_apply(true);
  return problem;
}

// "dir/left%02d.jpg" with index i; empty when the pattern has no single integer conversion.
std::string FormatPattern(const std::string& pattern, int index) {
  const size_t percent = pattern.find('%');
  if (percent == std::string::npos || pattern.find('%', percent + 1) != std::string::npos)
    return "";
  size_t end = percent + 1;
  while (end < pattern.size() && std::isdigit(static_cast<unsigned char>(pattern[end]))) ++end;
  if (end >= pattern.size() || pattern[end] != 'd') return "";
  std::vector<char> buffer(pattern.size() + 32);
  std::snprintf(buffer.data(), buffer.size(), pattern.c_str(), index);
  return buffer.data();
}

// The server grabs the pairs from its own source while the board moves.
int FromCapture(Client& client, const CalibrateArgs& a) {
  v1::CaptureCalibrationRequest request;
  *request.mutable_settings() = a.settings;
  request.set_pairs(a.capture);
  request.set_interval_s(a.interval_s);
  v1::CalibrationReport report;
  const grpc::Status status = client.CaptureCalibration(request, [&](const v1::CaptureProgress& p) {
    if (p.has_report()) {
      report = p.report();
    } else if (!a.json) {
      const v1::CapturedPair& c = p.pair();
      std::cerr << "pair " << c.index() << "/" << c.of() << ": board "
                << (c.board_left() ? "left " : "") << (c.board_right() ? "right" : "")
                << (!c.board_left() && !c.board_right() ? "not found" : "") << "; coverage "
                << std::fixed << std::setprecision(0) << 100 * c.coverage_left() << " % / "
                << 100 * c.coverage_right() << " %\n";
    }
  });
  if (!status.ok()) return RpcFailed(client, "calibrate", status);
  PrintReport(report, a.json);
  return report.passed() ? 0 : 1;
}

// The image pairs that the patterns name, indices 0..9999 with gaps skipped, into `pairs`; false
// (after saying so) when one image of a pair is missing.
bool ReadPairs(const CalibrateArgs& a, std::vector<v1::ImagePair>& pairs) {
  for (int index = 0; index <= 9999; ++index) {
    const std::string left = FormatPattern(a.left_pattern, index);
    const std::string right = FormatPattern(a.right_pattern, index);
    v1::ImagePair pair;
    const bool have_left = ReadFile(left, *pair.mutable_left());
    const bool have_right = ReadFile(right, *pair.mutable_right());
    if (!have_left && !have_right) continue;
    if (have_left != have_right) {
      std::cerr << "stevi: calibrate: " << (have_left ? right : left) << " is missing (its pair "
                << (have_left ? left : right) << " exists)\n";
      return false;
    }
    pair.set_name(left.substr(left.find_last_of('/') + 1));
    pairs.push_back(std::move(pair));
  }
  return true;
}

// Uploads the image files that the patterns name.
int FromFiles(Client& client, const CalibrateArgs& a) {
  if (a.left_pattern.empty() || a.right_pattern.empty()) {
    return Usage("calibrate: --left and --right go together");
  }
  if (FormatPattern(a.left_pattern, 0).empty() || FormatPattern(a.right_pattern, 0).empty()) {
    return Usage(
        "calibrate: --left and --right must be printf patterns with one integer "
        "conversion, e.g. dir/left%02d.jpg");
  }
  std::vector<v1::ImagePair> pairs;
  if (!ReadPairs(a, pairs)) return 1;
  if (pairs.empty()) {
    std::cerr << "stevi: calibrate: no image pair matches " << a.left_pattern << " and "
              << a.right_pattern << "\n";
    return 1;
  }
  if (!a.json) std::cerr << "uploading " << pairs.size() << " pairs...\n";
  v1::CalibrationReport report;
  const grpc::Status status = client.Calibrate(a.settings, pairs, &report);
  if (!status.ok()) return RpcFailed(client, "calibrate", status);
  PrintReport(report, a.json);
  return report.passed() ? 0 : 1;
}

}  // namespace

int Calibrate(Client& client, const Args& args) {
  CalibrateArgs a;
  if (std::string problem = ParseArgs(args, a); !problem.empty()) return Usage(problem);
  if (!a.have_board || !a.have_square)
    return Usage("calibrate: --board and --square-mm are required");
  const bool upload = !a.left_pattern.empty() || !a.right_pattern.empty();
  if (upload == (a.capture > 0)) {
    return Usage("calibrate: give either --left and --right patterns, or --capture N");
  }
  return a.capture > 0 ? FromCapture(client, a) : FromFiles(client, a);
}

const CommandSpec kCalibrateCommand = {
    "calibrate", "stereo calibration from chessboard pairs, uploaded or captured",
    R"(usage: stevi calibrate --board COLSxROWS --square-mm MM [--apply] [--json]
                       [--min-pairs N] [--max-rms PX] [--max-epipolar PX] [--alpha A]
                       (--left PATTERN --right PATTERN | --capture N [--interval S])

Stereo calibration from chessboard pairs: uploaded image files (printf patterns with one
integer, e.g. dir/left%02d.jpg; indices 0..9999, gaps skipped) or N pairs the server grabs from
its own source every S seconds (default 0.5) while the board moves. Prints the quality report;
--apply activates the result if every gate passes. The board counts inner corners (e.g. 9x6).
)",
    &Calibrate};

}  // namespace stevi::client::commands
