// The deployment files of deploy/: the example configs load, validate and (the demo) really serve;
// the systemd unit has its hardening and passes `systemd-analyze verify`; the Containerfile builds
// from Debian packages only and runs unprivileged. They are not compiled, so only this test notices
// when a schema change, a renamed flag or a careless edit breaks them.
#include <signal.h>
#include <unistd.h>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "server/app_config.h"
#include "server/runtime/pose_source.h"
#include "tests/testing/data.h"
#include "tests/testing/subprocess.h"

namespace stevi::server {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;
using namespace std::chrono_literals;

// The repository (a compile definition: the files are read where they are, not copied).
std::string SourcePath(const std::string& relative) {
  return std::string(STEVI_SOURCE_DIR).append("/").append(relative);
}

std::string ReadText(const std::string& path) {
  std::ifstream in(path);
  EXPECT_TRUE(in.good()) << "cannot read " << path;
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) lines.push_back(line);
  return lines;
}

std::string Trim(const std::string& s) {
  const size_t begin = s.find_first_not_of(" \t\r");
  if (begin == std::string::npos) return "";
  return s.substr(begin, s.find_last_not_of(" \t\r") + 1 - begin);
}

// A program on $PATH (Subprocess runs argv[0] as given, without a search), or "".
std::string FindOnPath(const std::string& name) {
  const char* path = std::getenv("PATH");
  std::istringstream dirs(path != nullptr && *path != '\0' ? path : "/usr/bin:/bin");
  std::string dir;
  while (std::getline(dirs, dir, ':')) {
    const std::string candidate = (dir.empty() ? std::string(".") : dir).append("/").append(name);
    if (access(candidate.c_str(), X_OK) == 0) return candidate;
  }
  return "";
}

// Fails the test (not skips): the unit checks need systemd-analyze, and Debian 12 has it.
std::string SystemdAnalyze() {
  const std::string found = FindOnPath("systemd-analyze");
  EXPECT_FALSE(found.empty()) << "systemd-analyze is not installed (Debian package systemd, in "
                                 "deploy/install-deps.sh): the unit cannot be verified";
  return found;
}

// ---------------------------------------------------------------------------------------------
// The example configs.

const char* const kConfigNames[] = {"demo.textproto", "ground-rig.textproto",
                                    "telephoto-long-range.textproto", "vehicle-gps.textproto"};

v1::ServerConfig LoadOrFail(const std::string& name) {
  Result<v1::ServerConfig> config = LoadServerConfig(SourcePath("deploy/config/").append(name));
  EXPECT_TRUE(config.ok()) << config.error().message;
  return config.ok() ? *config : v1::ServerConfig();
}

TEST(DeployConfigs, TheDirectoryHoldsExactlyTheDocumentedConfigs) {
  // The unit, the container and the README name these; a renamed or extra file is noticed here,
  // and the loops below cannot silently test nothing.
  std::set<std::string> found;
  for (const fs::directory_entry& e : fs::directory_iterator(SourcePath("deploy/config"))) {
    if (e.path().extension() == ".textproto") found.insert(e.path().filename().string());
  }
  EXPECT_EQ(found, std::set<std::string>(std::begin(kConfigNames), std::end(kConfigNames)));
}

TEST(DeployConfigs, EveryConfigLoadsValidatesAndBuildsItsPipeline) {
  for (const char* name : kConfigNames) {
    SCOPED_TRACE(name);
    Result<v1::ServerConfig> config = LoadServerConfig(SourcePath("deploy/config/").append(name));
    ASSERT_TRUE(config.ok()) << config.error().message;
    // The start-up checks stevi-server makes before opening anything.
    EXPECT_THAT(ValidateServerConfig(*config), ::testing::IsEmpty());
    Result<pipeline::PipelineConfig> pipeline = BuildPipelineConfig(config->pipeline());
    EXPECT_TRUE(pipeline.ok()) << pipeline.error().message;
    // The geo block is checked when the server builds its pose source.
    Result<std::unique_ptr<PoseSource>> poses = MakePoseSource(config->geo(), std::nullopt);
    EXPECT_TRUE(poses.ok()) << poses.error().message;
    // All of them keep their state where the unit's StateDirectory and the container's VOLUME are.
    EXPECT_EQ(config->data_dir(), "/var/lib/stevi");
    // --allow-insecure is an operator's explicit choice, never an example's default.
    EXPECT_FALSE(config->allow_insecure());
  }
}

TEST(DeployConfigs, DemoIsTheSyntheticRigOnLoopback) {
  const v1::ServerConfig demo = LoadOrFail("demo.textproto");
  EXPECT_EQ(demo.listen(), "127.0.0.1:50051");
  EXPECT_EQ(demo.source().kind(), v1::SOURCE_KIND_SYNTHETIC);
  EXPECT_EQ(demo.pipeline().algorithm(), v1::ALGORITHM_CANONICAL);
  EXPECT_FALSE(demo.has_record());
}

TEST(DeployConfigs, VehicleTakesItsPoseFromTheAutopilotAndRecordsFromBoot) {
  const v1::ServerConfig vehicle = LoadOrFail("vehicle-gps.textproto");
  EXPECT_EQ(vehicle.source().kind(), v1::SOURCE_KIND_ARAVIS);
  EXPECT_FALSE(vehicle.source().calibration().empty());
  EXPECT_EQ(vehicle.pipeline().algorithm(), v1::ALGORITHM_STEVIS);
  EXPECT_DOUBLE_EQ(vehicle.pipeline().mount().pitch_deg(), -10);  // optical axis down
  // A fixed pose would georeference with a stale position until the first published state.
  EXPECT_FALSE(vehicle.geo().has_fixed_pose());
  EXPECT_TRUE(vehicle.geo().has_max_age_s());
  EXPECT_EQ(vehicle.record().dir(), "/var/lib/stevi/recordings/boot");
  EXPECT_EQ(vehicle.record().max_bytes(), 20'000'000'000u);
}

TEST(DeployConfigs, TelephotoRigLeavesTheDefaultsThatFollowTheRig) {
  const v1::ServerConfig tele = LoadOrFail("telephoto-long-range.textproto");
  EXPECT_EQ(tele.source().kind(), v1::SOURCE_KIND_ARAVIS);
  EXPECT_EQ(tele.source().aravis().width(), 1280u);
  EXPECT_EQ(tele.pipeline().algorithm(), v1::ALGORITHM_STEVIE);
  // The binning, the disparity floor and the detectors' sizes are the defaults, which follow the
  // rig (tests/core/pipeline/long_range_test runs this rig with them); only a site range limit.
  EXPECT_FALSE(tele.pipeline().has_max_width_px());
  EXPECT_FALSE(tele.pipeline().range().has_min_disparity_px());
  EXPECT_DOUBLE_EQ(tele.pipeline().range().max_range_m(), 1500);
  EXPECT_FALSE(tele.pipeline().has_stevie());
}

TEST(DeployConfigs, GroundRigSitsAtPisaRunway04RAndServesTheNetworkWithAuthentication) {
  const v1::ServerConfig ground = LoadOrFail("ground-rig.textproto");
  ASSERT_TRUE(ground.geo().has_fixed_pose());
  const v1::VehicleState& pose = ground.geo().fixed_pose();
  EXPECT_DOUBLE_EQ(pose.position().lat_deg(), 43.6839);
  EXPECT_DOUBLE_EQ(pose.position().lon_deg(), 10.3925);
  EXPECT_DOUBLE_EQ(pose.position().alt_m(), 55);
  EXPECT_DOUBLE_EQ(pose.yaw_deg(), 223);
  EXPECT_DOUBLE_EQ(ground.pipeline().mount().pitch_deg(), 5);  // optical axis up
  // Off loopback it must pass validation through real authentication, not --allow-insecure: TLS
  // and a token (checked above by ValidateServerConfig).
  EXPECT_THAT(ground.listen(), Not(HasSubstr("127.0.0.1")));
  EXPECT_TRUE(ground.tls().has_cert_file() && ground.tls().has_key_file());
  EXPECT_TRUE(ground.auth().has_token_file());
}

TEST(DeployConfigs, TheDemoConfigServesAndStopsWithExitZeroOnSigterm) {
  // The demo as the unit and the container run it, with only the address and the data directory
  // moved to where a test may write (flags override the file).
  const std::string data_dir = testing::MakeTempDir("stevi-deploy-data");
  testing::Subprocess server({testing::BinaryPath("stevi-server"), "--config",
                              SourcePath("deploy/config/demo.textproto"), "--listen", "127.0.0.1:0",
                              "--data-dir", data_dir});
  const std::optional<std::string> serving = server.WaitForStderrLine("serving", 60s);
  ASSERT_TRUE(serving.has_value()) << "stevi-server did not start: " << server.DrainStderr();
  // The config's source and algorithm are what runs, on the overriding loopback address.
  EXPECT_THAT(*serving, HasSubstr("synthetic"));
  EXPECT_THAT(*serving, HasSubstr("canonical"));
  EXPECT_TRUE(std::regex_search(*serving, std::regex("127\\.0\\.0\\.1:[1-9][0-9]*"))) << *serving;
  // systemd (KillSignal=SIGTERM) and container runtimes (STOPSIGNAL) stop it so: a clean shutdown
  // is exit 0, which Restart=on-failure does not restart. TimeoutStopSec is 10 s.
  server.Signal(SIGTERM);
  const std::optional<int> code = server.Wait(10s);
  ASSERT_TRUE(code.has_value()) << "no exit within TimeoutStopSec: " << server.DrainStderr();
  EXPECT_EQ(*code, 0) << server.DrainStderr();
}

// ---------------------------------------------------------------------------------------------
// The systemd unit.

// section -> key -> every value in file order (keys such as SystemCallFilter may repeat).
using UnitFile = std::map<std::string, std::map<std::string, std::vector<std::string>>>;

UnitFile ParseUnit(const std::string& text) {
  UnitFile unit;
  std::string section, pending;
  for (const std::string& raw : Lines(text)) {
    if (pending.empty() && (Trim(raw).empty() || Trim(raw)[0] == '#' || Trim(raw)[0] == ';')) {
      continue;
    }
    // As systemd reads it: a trailing backslash continues the directive, replaced by a space.
    const std::string piece = pending.empty() ? Trim(raw) : raw;
    if (!piece.empty() && piece.back() == '\\') {
      pending.append(piece.substr(0, piece.size() - 1)).append(" ");
      continue;
    }
    const std::string line = Trim(pending + piece);
    pending.clear();
    if (line.front() == '[') {
      EXPECT_EQ(line.back(), ']') << line;
      section = line.substr(1, line.size() - 2);
      continue;
    }
    const size_t eq = line.find('=');
    if (eq == std::string::npos) {
      ADD_FAILURE() << "not KEY=VALUE: " << line;
      continue;
    }
    EXPECT_FALSE(section.empty()) << "directive before any section: " << line;
    unit[section][Trim(line.substr(0, eq))].push_back(Trim(line.substr(eq + 1)));
  }
  EXPECT_TRUE(pending.empty()) << "the unit ends inside a continued directive";
  return unit;
}

// The one value of a key that must appear once ("" and a failure otherwise).
std::string One(const UnitFile& unit, const std::string& section, const std::string& key) {
  const auto s = unit.find(section);
  if (s == unit.end() || s->second.count(key) == 0) {
    ADD_FAILURE() << "[" << section << "] " << key << "= is missing";
    return "";
  }
  const std::vector<std::string>& values = s->second.at(key);
  EXPECT_EQ(values.size(), 1u) << key << " given " << values.size() << " times";
  return values.back();
}

std::string UnitText() { return ReadText(SourcePath("deploy/stevi-server.service")); }

TEST(SystemdUnit, RunsTheServerUnprivilegedAndSandboxed) {
  const UnitFile unit = ParseUnit(UnitText());
  const std::string s = "Service";
  EXPECT_EQ(One(unit, s, "ExecStart"),
            "/usr/local/bin/stevi-server --config /etc/stevi/server.textproto");
  const std::string user = One(unit, s, "User");
  EXPECT_FALSE(user.empty());
  EXPECT_NE(user, "root");
  EXPECT_NE(user, "0");
  EXPECT_EQ(One(unit, s, "Group"), user);
  EXPECT_EQ(One(unit, s, "StateDirectory"), "stevi");  // /var/lib/stevi, the configs' data_dir

  // Restarts after a failure, not forever, and not after a clean SIGTERM stop.
  EXPECT_EQ(One(unit, s, "Restart"), "on-failure");
  EXPECT_FALSE(One(unit, s, "RestartSec").empty());
  // StartLimitIntervalSec=0 (or an empty value) would turn the start limit off.
  const std::string interval = One(unit, "Unit", "StartLimitIntervalSec");
  EXPECT_FALSE(interval.empty() || interval == "0" || interval == "infinity") << interval;
  EXPECT_TRUE(std::regex_match(One(unit, "Unit", "StartLimitBurst"), std::regex("[1-9][0-9]*")));
  EXPECT_EQ(One(unit, s, "KillSignal"), "SIGTERM");
  EXPECT_EQ(One(unit, s, "TimeoutStopSec"), "10");

  // No privileges at all: an empty bounding set removes every capability for good.
  EXPECT_EQ(One(unit, s, "CapabilityBoundingSet"), "");
  EXPECT_EQ(One(unit, s, "AmbientCapabilities"), "");
  const std::map<std::string, std::string> hardening = {
      {"NoNewPrivileges", "yes"},
      {"ProtectSystem", "strict"},
      {"ProtectHome", "yes"},
      {"PrivateTmp", "yes"},
      {"ProtectKernelTunables", "yes"},
      {"ProtectKernelModules", "yes"},
      {"ProtectControlGroups", "yes"},
      {"RestrictNamespaces", "yes"},
      {"LockPersonality", "yes"},
      {"MemoryDenyWriteExecute", "yes"},
      {"RestrictRealtime", "yes"},
      {"SystemCallArchitectures", "native"},
      {"UMask", "0077"},
      {"DevicePolicy", "closed"},
  };
  for (const auto& [key, value] : hardening) EXPECT_EQ(One(unit, s, key), value) << key;
  EXPECT_FALSE(One(unit, s, "LimitNOFILE").empty());

  // Exactly the socket families the server and Aravis use (no AF_PACKET, no raw sockets).
  std::istringstream families(One(unit, s, "RestrictAddressFamilies"));
  std::set<std::string> family_set{std::istream_iterator<std::string>(families), {}};
  EXPECT_EQ(family_set, (std::set<std::string>{"AF_INET", "AF_INET6", "AF_UNIX", "AF_NETLINK"}));
  // USB3 Vision cameras: the real /dev (PrivateDevices=no), but only USB device nodes.
  EXPECT_EQ(One(unit, s, "PrivateDevices"), "no");
  EXPECT_EQ(One(unit, s, "DeviceAllow"), "char-usb_device rw");

  EXPECT_EQ(One(unit, "Install", "WantedBy"), "multi-user.target");
}

// The ExecStartPre script as /bin/sh receives it: systemd turns "$$" into "$" and "%%" into "%".
// A lone "$name" would be expanded by systemd itself (to nothing), a lone "%x" is a specifier.
std::string ShellScriptOfExecStartPre(const std::string& value) {
  const std::string prefix = "/bin/sh -c '";
  EXPECT_EQ(value.rfind(prefix, 0), 0u) << value;
  EXPECT_EQ(value.back(), '\'') << value;
  if (value.rfind(prefix, 0) != 0 || value.size() < prefix.size() + 1) return "";
  const std::string escaped = value.substr(prefix.size(), value.size() - prefix.size() - 1);
  std::string script;
  for (size_t i = 0; i < escaped.size(); ++i) {
    const char c = escaped[i];
    if (c == '$' || c == '%') {
      EXPECT_TRUE(i + 1 < escaped.size() && escaped[i + 1] == c)
          << "unescaped '" << c << "' at " << i << " of: " << escaped;
      ++i;
    }
    script.push_back(c);
  }
  return script;
}

TEST(SystemdUnit, MovesThePreviousBootRecordingAsideBeforeStarting) {
  // vehicle-gps records from the start into a fixed directory, and the server refuses one that
  // holds a recording: without this step no start after the first would succeed.
  const UnitFile unit = ParseUnit(UnitText());
  std::string script = ShellScriptOfExecStartPre(One(unit, "Service", "ExecStartPre"));
  const std::string boot = LoadOrFail("vehicle-gps.textproto").record().dir();
  ASSERT_THAT(script, HasSubstr(boot)) << "the unit and vehicle-gps.textproto disagree";

  // Run it on a temporary /var/lib/stevi.
  const std::string root = testing::MakeTempDir("stevi-deploy-state");
  const std::string state = "/var/lib/stevi";
  for (size_t at; (at = script.find(state)) != std::string::npos;) {
    script.replace(at, state.size(), root);
  }
  const std::string recordings = root + "/recordings";
  fs::create_directories(recordings + "/boot");
  std::ofstream(recordings + "/boot/manifest.json") << "{}\n";

  testing::RunResult first = testing::Run({"/bin/sh", "-c", script}, 30s);
  ASSERT_EQ(first.exit_code, 0) << first.err;
  EXPECT_FALSE(fs::exists(recordings + "/boot"));
  std::vector<std::string> moved;
  for (const fs::directory_entry& e : fs::directory_iterator(recordings)) {
    moved.push_back(e.path().filename().string());
  }
  ASSERT_EQ(moved.size(), 1u);
  EXPECT_TRUE(std::regex_match(moved[0], std::regex("boot-[0-9]{8}T[0-9]{6}Z"))) << moved[0];
  EXPECT_TRUE(fs::exists(recordings + "/" + moved[0] + "/manifest.json"));

  // Nothing to move (the first boot, or a config that does not record): a no-op, not a failure.
  testing::RunResult again = testing::Run({"/bin/sh", "-c", script}, 30s);
  EXPECT_EQ(again.exit_code, 0) << again.err;
  EXPECT_EQ(std::distance(fs::directory_iterator(recordings), fs::directory_iterator()), 1);
}

// A copy of the unit in a new directory with ExecStart on the built binary (verify checks that the
// program exists and is executable; /usr/local/bin/stevi-server is not installed here).
std::string UnitCopyForBuiltBinary() {
  std::string text = UnitText();
  const std::string installed = "ExecStart=/usr/local/bin/stevi-server ";
  const size_t at = text.find(installed);
  EXPECT_NE(at, std::string::npos);
  if (at != std::string::npos) {
    text.replace(at, installed.size(),
                 std::string("ExecStart=").append(testing::BinaryPath("stevi-server")).append(" "));
  }
  const std::string path = testing::MakeTempDir("stevi-deploy-unit") + "/stevi-server.service";
  std::ofstream(path) << text;
  return path;
}

TEST(SystemdUnit, SystemdAnalyzeVerifyAcceptsIt) {
  const std::string analyze = SystemdAnalyze();
  ASSERT_FALSE(analyze.empty());
  const std::string unit = UnitCopyForBuiltBinary();
  const testing::RunResult verify = testing::Run({analyze, "verify", unit}, 60s);
  EXPECT_EQ(verify.exit_code, 0) << verify.out << verify.err;
  // An unknown directive or a bad value is only a warning (exit 0): any line naming the unit fails.
  for (const std::string& line : Lines(verify.out + verify.err)) {
    EXPECT_THAT(line, Not(HasSubstr("stevi-server.service"))) << "systemd-analyze verify: " << line;
  }
}

TEST(SystemdUnit, SystemdAnalyzeSecurityRatesTheExposureLow) {
  const std::string analyze = SystemdAnalyze();
  ASSERT_FALSE(analyze.empty());
  const std::string unit = UnitCopyForBuiltBinary();
  // --offline reads the file without a running systemd (systemd >= 250; Debian 12 has 252).
  const testing::RunResult security =
      testing::Run({analyze, "security", "--offline=true", "--no-pager", unit}, 60s);
  if (security.exit_code != 0 && security.err.find("unrecognized option") != std::string::npos) {
    GTEST_SKIP() << "this systemd-analyze cannot rate a unit offline: " << security.err;
  }
  ASSERT_EQ(security.exit_code, 0) << security.out << security.err;
  std::smatch m;
  ASSERT_TRUE(
      std::regex_search(security.out, m, std::regex("Overall exposure level for [^:]+: ([0-9.]+)")))
      << security.out;
  const double exposure = std::stod(m[1].str());
  std::cout << "systemd-analyze security: exposure " << exposure << " (0 best, 10 worst)\n";
  // 1.6 as written; the network and USB access it needs cost about 1. Above 2.5 some hardening
  // directive was dropped or weakened.
  EXPECT_LE(exposure, 2.5) << security.out;
}

// ---------------------------------------------------------------------------------------------
// The Containerfile (not built here: that needs a registry; checked as text).

struct Instruction {
  std::string keyword;  // FROM, RUN, ... (upper case as written)
  std::string args;     // the rest, continuation lines joined
};

std::vector<Instruction> ParseContainerfile(const std::string& text) {
  std::vector<Instruction> out;
  std::string pending;
  for (const std::string& raw : Lines(text)) {
    const std::string line = Trim(raw);
    if (pending.empty() && (line.empty() || line[0] == '#')) continue;
    if (!line.empty() && line[0] == '#') continue;  // a comment inside a continued instruction
    if (!line.empty() && line.back() == '\\') {
      pending.append(line.substr(0, line.size() - 1)).append(" ");
      continue;
    }
    pending.append(line);
    const size_t space = pending.find_first_of(" \t");
    out.push_back({pending.substr(0, space),
                   space == std::string::npos ? "" : Trim(pending.substr(space + 1))});
    pending.clear();
  }
  EXPECT_TRUE(pending.empty()) << "the file ends inside a continued instruction";
  return out;
}

std::vector<std::string> Words(const std::string& s) {
  std::istringstream in(s);
  return {std::istream_iterator<std::string>(in), {}};
}

TEST(Containerfile, BuildsFromDebianPackagesAndRunsUnprivileged) {
  const std::vector<Instruction> file =
      ParseContainerfile(ReadText(SourcePath("deploy/Containerfile")));
  ASSERT_FALSE(file.empty());
  size_t last_from = 0;
  std::string user, entrypoint, cmake_configure;
  bool exposes = false, volume = false, runs_install_deps = false, copies_demo = false;
  for (size_t i = 0; i < file.size(); ++i) {
    const Instruction& in = file[i];
    SCOPED_TRACE(in.keyword + " " + in.args);
    // Nothing fetched from the network but Debian packages: no ADD (it takes URLs), no curl, no
    // wget, no URL at all in an instruction.
    EXPECT_NE(in.keyword, "ADD");
    for (const char* fetch : {"curl", "wget", "http://", "https://", "git clone"}) {
      EXPECT_THAT(in.args, Not(HasSubstr(fetch)));
    }
    EXPECT_THAT(in.args, Not(HasSubstr("--allow-insecure")));
    if (in.keyword == "FROM") {
      last_from = i;
      user.clear();  // USER does not carry over into a new stage
      EXPECT_EQ(in.args.rfind("debian:bookworm", 0), 0u) << "base image: " << in.args;
    }
    if (in.keyword == "USER") user = in.args;
    if (in.keyword == "EXPOSE" && Words(in.args) == std::vector<std::string>{"50051"}) {
      exposes = true;
    }
    if (in.keyword == "VOLUME" && in.args == "/var/lib/stevi") volume = true;
    if (in.keyword == "ENTRYPOINT") entrypoint = in.args;
    if (in.keyword == "RUN" && in.args.find("deploy/install-deps.sh") != std::string::npos) {
      runs_install_deps = true;
    }
    if (in.keyword == "RUN" && in.args.find("cmake -S") != std::string::npos) {
      cmake_configure = in.args;
    }
    if (in.keyword == "COPY" &&
        Words(in.args) == std::vector<std::string>{"deploy/config/demo.textproto",
                                                   "/etc/stevi/server.textproto"}) {
      copies_demo = true;
    }
    // Every source the build context must provide exists in the repository.
    if (in.keyword == "COPY" && in.args.rfind("--from=", 0) != 0) {
      const std::vector<std::string> words = Words(in.args);
      ASSERT_GE(words.size(), 2u);
      for (size_t w = 0; w + 1 < words.size(); ++w) {
        EXPECT_TRUE(fs::exists(SourcePath(words[w]))) << words[w] << " is not in the repository";
      }
    }
  }
  // The final stage runs as a named non-root uid.
  const std::string user_name = user.substr(0, user.find(':'));
  EXPECT_FALSE(user_name.empty()) << "no USER in the final stage (from instruction " << last_from
                                  << "): it would run as root";
  EXPECT_NE(user_name, "root");
  EXPECT_NE(user_name, "0");
  EXPECT_TRUE(exposes) << "EXPOSE 50051";
  EXPECT_TRUE(volume) << "VOLUME /var/lib/stevi";
  EXPECT_TRUE(runs_install_deps) << "the packages come from deploy/install-deps.sh";
  EXPECT_TRUE(copies_demo) << "the demo config is the default /etc/stevi/server.textproto";
  EXPECT_EQ(entrypoint,
            R"(["/usr/local/bin/stevi-server", "--config", "/etc/stevi/server.textproto"])");
  EXPECT_THAT(cmake_configure, HasSubstr("-DCMAKE_BUILD_TYPE=RelWithDebInfo"));
  EXPECT_THAT(cmake_configure, HasSubstr("-DSTEVI_BUILD_TESTS=OFF"));
  EXPECT_THAT(cmake_configure, HasSubstr("-DSTEVI_BUILD_BENCHMARKS=OFF"));
}

TEST(Containerfile, TheSourcesItCopiesAreEnoughToConfigure) {
  // The image copies a subset of the repository (not a local build/ tree). Configure exactly that
  // subset with the image's options, so that a new top-level folder the build needs is noticed.
  const std::vector<Instruction> file =
      ParseContainerfile(ReadText(SourcePath("deploy/Containerfile")));
  const std::string context = testing::MakeTempDir("stevi-deploy-context");
  for (const Instruction& in : file) {
    if (in.keyword != "COPY" || in.args.rfind("--from=", 0) == 0) continue;
    const std::vector<std::string> words = Words(in.args);
    const std::string& dest = words.back();
    if (dest.rfind("/src/", 0) != 0) continue;  // the runtime stage's files
    for (size_t w = 0; w + 1 < words.size(); ++w) {
      // "COPY a /src/" puts a in /src; "COPY dir /src/dir" makes /src/dir.
      const fs::path in_src = fs::path(context) / dest.substr(5);
      const fs::path target = dest.back() == '/' ? in_src / fs::path(words[w]).filename() : in_src;
      fs::create_directories(target.parent_path());
      fs::copy(SourcePath(words[w]), target, fs::copy_options::recursive);
    }
  }
  ASSERT_TRUE(fs::exists(fs::path(context) / "CMakeLists.txt"));
  const testing::RunResult configure =
      testing::Run({STEVI_CMAKE_COMMAND, "-S", context, "-B", context + "/build",
                    "-DCMAKE_BUILD_TYPE=RelWithDebInfo", "-DSTEVI_BUILD_TESTS=OFF",
                    "-DSTEVI_BUILD_BENCHMARKS=OFF"},
                   300s);
  EXPECT_EQ(configure.exit_code, 0) << configure.out << configure.err;
}

}  // namespace
}  // namespace stevi::server
