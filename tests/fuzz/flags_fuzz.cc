// Fuzz target: command-line arguments, through the one flag library (core/common/flags.h): a
// FlagSet and the number parser as the `stevi` tool uses them, and stevi-server's command line
// (server/server_flags.h: every setting's flag) applied over a ServerConfig, then its validation.
//
// Input: byte 0 picks the library; the rest is the argument list, split at '\0' bytes.
// Checked besides the sanitizers:
//   - an accepted number lies in its flag's range and is finite, and a rejected one left the
//     value untouched (the handler was not called);
//   - FormatNumber of an accepted real reads back as the same value;
//   - a parse either succeeds or returns an error message that names the problem (non-empty);
//   - applying the settings' flags either succeeds or leaves the config exactly as it was.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "core/common/flags.h"
#include "server/app_config.h"
#include "server/server_flags.h"
#include "tests/fuzz/require.h"

namespace flags = stevi::flags;

namespace {

using stevi::fuzz::Require;

std::vector<std::string> Split(const uint8_t* data, size_t size) {
  std::vector<std::string> args(1);
  for (size_t i = 0; i < size; ++i) {
    if (data[i] == 0) {
      args.emplace_back();
    } else {
      args.back().push_back(static_cast<char>(data[i]));
    }
  }
  return args;
}

bool InRange(double v, const flags::RealRange& r) {
  return std::isfinite(v) && (r.lo_open ? v > r.lo : v >= r.lo) && v <= r.hi;
}

void FuzzFlagSet(const std::vector<std::string>& args) {
  const flags::RealRange metres{0.1, 10000, "metres"};
  const flags::RealRange seconds{0, 3600, "seconds", true};
  const flags::WholeRange count{1, 1000, "a whole number"};
  bool verbose = false, help = false;
  std::string name = "unset";
  double range_m = -1, every_s = -1;
  std::int64_t n = -1;
  std::string pair;
  flags::FlagSet set("watch");
  set.Switch("--verbose", &verbose)
      .Stop("--help", &help)
      .Text("--name", &name)
      .Real("--range", metres,
            [&](double v) {
              Require(InRange(v, metres));
              range_m = v;
            })
      .Real("--every", seconds,
            [&](double v) {
              Require(InRange(v, seconds));
              every_s = v;
            })
      .Whole("--count", count,
             [&](std::int64_t v) {
               Require(v >= count.lo && v <= count.hi);
               n = v;
             })
      .Value("--board", [&](const std::string& v) -> std::string {
        const auto p = flags::ParseNumberPair(v, 'x', {2, 100, "corners"});
        if (!p.ok()) return "watch --board: " + std::string(flags::NumberProblemName(p.problem));
        Require(p.value.first >= 2 && p.value.first <= 100);
        Require(p.value.second >= 2 && p.value.second <= 100);
        pair = v;
        return "";
      });
  const std::string error = set.Parse(args, 1);
  Require(error.empty() || error.find("watch") != std::string::npos);
  std::size_t next = 1;
  const std::string leading = set.ParseLeading(args, next);
  Require(next >= 1 && next <= args.size());
  // Without a problem, every argument it took is an option.
  for (std::size_t i = 1; leading.empty() && i < next; ++i) {
    Require(args[i].rfind("--", 0) == 0 || args[i - 1].rfind("--", 0) == 0);
  }

  for (const std::string& a : args) {
    const auto real = flags::ParseNumber(a, flags::RealRange{-1e300, 1e300, ""});
    if (real.ok()) {
      Require(std::isfinite(real.value));
      const std::string text = flags::FormatNumber(real.value);
      const auto back = flags::ParseNumber(text, flags::RealRange{-1e300, 1e300, ""});
      Require(back.ok() && back.value == real.value);
    }
    const auto whole = flags::ParseNumber(a, flags::WholeRange{});
    Require(!whole.ok() || whole.value >= 0);
    Require(!flags::NumberProblemName(whole.problem).empty());
  }
}

void FuzzServerFlags(const std::vector<std::string>& args) {
  stevi::server::ServerCommandLine command_line(
      "stevi-server", [](const stevi::server::SettingFlag&) { return true; });
  std::vector<const char*> argv;
  argv.reserve(args.size());
  for (const std::string& a : args) argv.push_back(a.c_str());
  if (const std::string problem = command_line.Parse(static_cast<int>(argv.size()), argv.data());
      !problem.empty()) {
    return;
  }
  stevi::v1::ServerConfig config;
  config.set_listen("127.0.0.1:50051");
  const std::string before = config.SerializeAsString();
  const stevi::Status applied = command_line.ApplyTo(config);
  if (!applied.ok()) {
    Require(!applied.error().message.empty());
    Require(config.SerializeAsString() == before);
    return;
  }
  for (const std::string& problem : stevi::server::ValidateServerConfig(config)) {
    Require(!problem.empty());
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const std::vector<std::string> args = Split(data + 1, size - 1);
  if (data[0] & 1) {
    FuzzServerFlags(args);
  } else {
    FuzzFlagSet(args);
  }
  return 0;
}
