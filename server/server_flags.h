// The command-line flags of stevi-server and stevi-process, made from the field lists: every field
// marked Flag() in the server's settings (server/server_options.h), the pipeline's, the drivers'
// and the recorders' lists is a flag that sets its stevi.v1.ServerConfig field. Its parsing,
// bounds, usage line and README row all come from the field's one declaration.
#pragma once

#include <functional>
#include <optional>
#include <string_view>
#include <string>
#include <vector>

#include "core/common/error.h"
#include "core/common/fields.h"
#include "core/common/flags.h"
#include "stevi/v1/config.pb.h"

namespace stevi::server {

// One flag of a field (or of two: --roi WxH sets width and height, --trigger hardware:LINE sets
// the trigger and its line).
struct SettingFlag {
  enum class Kind {
    kNumber,  // a number within the field's bounds (a whole one for an integer field)
    kText,
    kSwitch,         // a bool field: the flag alone sets it
    kChoice,         // one of the names ('-' or '_' between words; a first word alone when unique)
    kPair,           // two numbers, "WxH"
    kChoiceAndText,  // "CHOICE" or "CHOICE:TEXT"
  };

  std::string flag;                // "exposure-us" (no dashes in front)
  std::vector<std::string> paths;  // "source.aravis.exposure_us"; two for kPair, kChoiceAndText
  Kind kind = Kind::kText;
  bool whole = false;        // kNumber, kPair: an integer field
  std::string metavar;       // "N", "FILE", "WxH"
  fields::Field field{""};   // the (first) field: bounds, unit, meaning
  fields::Field second{""};  // kPair: the second number's field (its own bounds)
  std::vector<std::string> choices;
  std::string default_value;  // as the usage shows it; empty when there is none
};

// Every flag, in the order of the field lists: the server's settings, then the source kinds'
// options, the recorders', the pipeline's.
const std::vector<SettingFlag>& SettingFlags();

// "  --HEAD" and its help wrapped in a column, as every usage line of the servers is.
std::string FormatUsageLine(const std::string& head, const std::string& help);

// The flag's usage line(s): "  --fps N   frames per second ... (Hz, in (0, 1000]; default 10)".
std::string UsageLine(const SettingFlag& flag);

// Sets the flag's field(s) in `config` from `text`. "" when done; else the problem, naming the
// flag and what it takes ("--fps: must be in (0, 1000] Hz (got '0')"), and `config` is unchanged.
std::string ApplySettingFlag(const SettingFlag& flag, const std::string& text,
                             v1::ServerConfig& config);

// The command line of a server program: the settings' flags it accepts, --config FILE and --help,
// plus the program's own flags, through the one flag library (core/common/flags.h).
class ServerCommandLine {
 public:
  // `program` begins the usage and the errors; `accepts` picks the settings' flags it takes.
  ServerCommandLine(std::string program, std::function<bool(const SettingFlag&)> accepts);

  // The program's own flags ("--frames"), each with its usage: add them before Parse.
  flags::FlagSet& own() { return own_; }
  void Describe(const std::string& flag, const std::string& metavar, const std::string& help);

  // Reads the arguments (argv[1..]); "" when they are well formed, else the first problem.
  // Values are checked by Config().
  std::string Parse(int argc, const char* const* argv);
  bool help() const { return help_; }
  // Parse, as a main does it: on --help prints Usage(about) and returns 0; on a problem prints it
  // to stderr and returns 2; nullopt when the program goes on.
  std::optional<int> ParseOrExit(int argc, const char* const* argv, const std::string& about);
  // Whether the setting's flag ("mcap-image-hz") was given.
  bool Given(std::string_view flag) const;

  // The config file of --config (if given) with the settings' flags over it, in the order given.
  // Every bad flag value is named; nothing is opened.
  Result<v1::ServerConfig> Config() const;
  // The settings' flags over `config`; on a problem `config` is left as it was.
  Status ApplyTo(v1::ServerConfig& config) const;

  // "usage: PROGRAM [flags]", `about`, then a line per flag, the program's own first.
  std::string Usage(const std::string& about) const;

 private:
  std::string program_;
  std::vector<const SettingFlag*> accepted_;
  flags::FlagSet own_;
  std::string own_usage_;
  std::string config_file_;
  bool help_ = false;
  std::vector<std::pair<const SettingFlag*, std::string>> given_;
};

// The flags of `settings` applied over `config`: each named problem, and then `config` unchanged.
Status ApplySettingFlags(const std::vector<std::pair<const SettingFlag*, std::string>>& settings,
                         v1::ServerConfig& config);

// The README's table of the flags: flag, config field, default, valid values, meaning.
std::string FlagTableMarkdown();

}  // namespace stevi::server
