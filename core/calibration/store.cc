#include "core/calibration/store.h"

#include "core/common/atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

namespace stevi::calibration {
namespace {

namespace fs = std::filesystem;

constexpr const char* kActiveFile = "active";
constexpr const char* kPrefix = "cal-";
constexpr const char* kCalibrationSuffix = ".yaml";
constexpr const char* kReportSuffix = ".report.yaml";
// Files larger than this are not read (a calibration and its report are a few kB).
constexpr std::uintmax_t kMaxFileBytes = 16u << 20;

// The whole file, or an error naming it (kNotFound when it does not exist).
Result<std::string> ReadFile(const std::string& path, const std::string& label) {
  std::error_code ec;
  if (!fs::exists(path, ec)) return NotFound(label + ": missing");
  const std::uintmax_t size = fs::file_size(path, ec);
  if (ec) return InvalidArgument(label + ": cannot read (" + ec.message() + ")");
  if (size > kMaxFileBytes) {
    return InvalidArgument(label + ": " + std::to_string(size) + " bytes, too large to be ours");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) return InvalidArgument(label + ": cannot open");
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) return InvalidArgument(label + ": read failed");
  return text.str();
}

// "cal-000012.yaml" -> 12 for any file of an entry (including temporary files
// "cal-000012.yaml.tmp-*").
std::optional<std::int64_t> IdOfFileName(const std::string& name) {
  if (name.rfind(kPrefix, 0) != 0) return std::nullopt;
  const std::size_t dot = name.find('.');
  if (dot == std::string::npos) return std::nullopt;
  const std::optional<CalibrationId> id = CalibrationId::Parse(name.substr(0, dot));
  if (!id) return std::nullopt;
  return id->value;
}

std::string Trim(const std::string& s) {
  const std::size_t b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return {};
  const std::size_t e = s.find_last_not_of(" \t\r\n");
  return s.substr(b, e - b + 1);
}

CalibrationSummary Summarise(CalibrationId id, const geometry::StereoCalibration& c,
                             const CalibrationReport& r) {
  CalibrationSummary s;
  s.id = id;
  s.created_unix_ms = r.created_unix_ms;
  s.rms_px = r.rms_px;
  s.passed = r.passed;
  s.swap_left_right = r.swap_left_right;
  s.baseline_m = cv::norm(c.T);
  s.image_size = c.image_size;
  return s;
}

// Replaces a leading "<full path>: " by "<file name>: " in a message from calibration_io.
std::string WithFileName(std::string message, const std::string& path,
                         const std::string& file_name) {
  if (message.rfind(path + ": ", 0) == 0) message = file_name + message.substr(path.size());
  if (message.rfind(file_name, 0) != 0) message = file_name + ": " + message;
  return message;
}

std::string Printable(const std::string& s) {
  std::string out;
  for (char ch : s.substr(0, 40)) out += (ch >= 32 && ch < 127) ? ch : '?';
  if (s.size() > 40) out += "...";
  return out;
}

}  // namespace

std::string CalibrationId::Name() const {
  char buf[32];
  std::snprintf(buf, sizeof buf, "cal-%06lld", static_cast<long long>(value));
  return buf;
}

std::optional<CalibrationId> CalibrationId::Parse(const std::string& name) {
  if (name.rfind(kPrefix, 0) != 0) return std::nullopt;
  const std::string digits = name.substr(4);
  if (digits.empty() || digits.size() > 15) return std::nullopt;
  std::int64_t v = 0;
  for (char ch : digits) {
    if (ch < '0' || ch > '9') return std::nullopt;
    v = v * 10 + (ch - '0');
  }
  if (v <= 0) return std::nullopt;
  return CalibrationId{v};
}

std::string CalibrationStore::CalibrationPath(CalibrationId id) const {
  return (fs::path(directory_) / (id.Name() + kCalibrationSuffix)).string();
}

std::string CalibrationStore::ReportPath(CalibrationId id) const {
  return (fs::path(directory_) / (id.Name() + kReportSuffix)).string();
}

namespace {

// The ids of a store's files: the largest of any file (temporary ones included), and those of its
// calibrations and its reports.
struct StoreFiles {
  std::int64_t max_id = 0;
  std::set<std::int64_t> calibration_ids, report_ids;
};

Status ListStoreFiles(const std::string& directory, StoreFiles& files) {
  std::error_code ec;
  fs::directory_iterator it(directory, ec);
  if (ec) {
    return InvalidArgument("calibration store: cannot list " + directory + " (" + ec.message() +
                           ")");
  }
  for (const fs::directory_entry& entry : it) {
    const std::string name = entry.path().filename().string();
    const std::optional<std::int64_t> id = IdOfFileName(name);
    if (!id) continue;
    files.max_id = std::max(files.max_id, *id);
    if (name == CalibrationId{*id}.Name() + kCalibrationSuffix) files.calibration_ids.insert(*id);
    if (name == CalibrationId{*id}.Name() + kReportSuffix) files.report_ids.insert(*id);
  }
  return Status::Ok();
}

}  // namespace

Result<OpenedStore> CalibrationStore::Open(const std::string& directory) {
  std::error_code ec;
  if (directory.empty()) return InvalidArgument("calibration store: empty directory name");
  if (fs::exists(directory, ec) && !fs::is_directory(directory, ec)) {
    return InvalidArgument("calibration store: " + directory + " is not a directory");
  }
  fs::create_directories(directory, ec);
  if (!fs::is_directory(directory, ec)) {
    return InvalidArgument("calibration store: cannot create the directory " + directory + " (" +
                           ec.message() + ")");
  }

  OpenedStore opened;
  opened.store.reset(new CalibrationStore(directory));
  CalibrationStore& store = *opened.store;
  StoreFiles files;
  if (Status listed = ListStoreFiles(directory, files); !listed.ok()) return listed.error();
  // Why each unreadable id was left out, for the message about a dangling `active`.
  std::map<std::int64_t, std::string> left_out;
  store.LoadEntries(files.calibration_ids, files.report_ids, opened.problems, left_out);
  store.LoadActive(left_out, files.max_id, opened.problems);
  store.next_id_ = files.max_id + 1;
  return opened;
}

void CalibrationStore::LoadEntries(const std::set<std::int64_t>& calibration_ids,
                                   const std::set<std::int64_t>& report_ids,
                                   std::vector<std::string>& problems,
                                   std::map<std::int64_t, std::string>& left_out) {
  for (std::int64_t raw : report_ids) {
    if (!calibration_ids.count(raw)) {
      const CalibrationId id{raw};
      problems.push_back(id.Name() + kReportSuffix +
                         ": no calibration file beside it (an interrupted Add?); left out");
      left_out[raw] = "has no calibration file";
    }
  }
  for (std::int64_t raw : calibration_ids) {
    const CalibrationId id{raw};
    const std::string yaml_name = id.Name() + kCalibrationSuffix;
    const std::string report_name = id.Name() + kReportSuffix;
    Result<geometry::StereoCalibration> calibration =
        geometry::LoadCalibrationYaml(CalibrationPath(id));
    if (!calibration.ok()) {
      problems.push_back(WithFileName(calibration.error().message, CalibrationPath(id), yaml_name));
      left_out[raw] = "is unreadable";
      continue;
    }
    Result<std::string> report_text = ReadFile(ReportPath(id), report_name);
    if (!report_text.ok()) {
      problems.push_back(report_text.error().message + "; " + id.Name() + " is left out");
      left_out[raw] = "has no readable report";
      continue;
    }
    Result<CalibrationReport> report = ParseReportYaml(*report_text);
    if (!report.ok()) {
      problems.push_back(report_name + ": " + report.error().message + "; " + id.Name() +
                         " is left out");
      left_out[raw] = "has no readable report";
      continue;
    }
    entries_.push_back(Summarise(id, *calibration, *report));
  }
}

void CalibrationStore::LoadActive(const std::map<std::int64_t, std::string>& left_out,
                                  std::int64_t& max_id, std::vector<std::string>& problems) {
  std::optional<CalibrationId> last_good;
  for (const CalibrationSummary& s : entries_) {
    if (s.passed) last_good = s.id;
  }
  const std::string fallback = last_good ? "using " + last_good->Name() + " (the last good one)"
                                         : std::string("no calibration is active");
  const std::string active_path = (fs::path(directory_) / kActiveFile).string();
  Result<std::string> active_text = ReadFile(active_path, kActiveFile);
  if (active_text.ok()) {
    const std::string text = Trim(*active_text);
    const std::optional<CalibrationId> named = CalibrationId::Parse(text);
    if (!named) {
      problems.push_back(std::string("active: cannot read \"") + Printable(text) +
                         "\" as a calibration id; " + fallback);
      active_ = last_good;
    } else {
      max_id = std::max(max_id, named->value);
      const auto entry = std::find_if(entries_.begin(), entries_.end(),
                                      [&](const CalibrationSummary& s) { return s.id == *named; });
      if (entry == entries_.end()) {
        const auto why = left_out.find(named->value);
        const std::string state =
            why != left_out.end() ? why->second
                                  : "is missing (no " + named->Name() + kCalibrationSuffix + ")";
        problems.push_back("active: points to " + named->Name() + ", which " + state + "; " +
                           fallback);
        active_ = last_good;
      } else if (!entry->passed) {
        problems.push_back("active: points to " + named->Name() +
                           ", which failed its quality gates; " + fallback);
        active_ = last_good;
      } else {
        active_ = named;
      }
    }
  } else if (active_text.error().code != ErrorCode::kNotFound) {
    problems.push_back(active_text.error().message + "; " + fallback);
    active_ = last_good;
  }
}

std::vector<CalibrationSummary> CalibrationStore::List() const {
  std::lock_guard<std::mutex> lock(mu_);
  return entries_;
}

Result<StoredCalibration> CalibrationStore::ReadLocked(CalibrationId id) const {
  const bool known = std::any_of(entries_.begin(), entries_.end(),
                                 [&](const CalibrationSummary& s) { return s.id == id; });
  if (!known) return NotFound("no calibration " + id.Name() + " in " + directory_);
  const std::string yaml_name = id.Name() + kCalibrationSuffix;
  const std::string report_name = id.Name() + kReportSuffix;
  StoredCalibration out;
  out.id = id;
  Result<std::string> yaml = ReadFile(CalibrationPath(id), yaml_name);
  if (!yaml.ok()) return yaml.error();
  Result<geometry::StereoCalibration> calibration = geometry::ParseCalibrationYaml(*yaml);
  if (!calibration.ok()) {
    return InvalidArgument(yaml_name + ": " + calibration.error().message);
  }
  Result<std::string> report_text = ReadFile(ReportPath(id), report_name);
  if (!report_text.ok()) return report_text.error();
  Result<CalibrationReport> report = ParseReportYaml(*report_text);
  if (!report.ok()) return InvalidArgument(report_name + ": " + report.error().message);
  out.yaml_text = std::move(*yaml);
  out.calibration = std::move(*calibration);
  out.report = std::move(*report);
  return out;
}

Result<StoredCalibration> CalibrationStore::Get(CalibrationId id) const {
  std::lock_guard<std::mutex> lock(mu_);
  return ReadLocked(id);
}

Result<CalibrationId> CalibrationStore::Add(const geometry::StereoCalibration& calibration,
                                            const CalibrationReport& report) {
  if (std::vector<std::string> problems = calibration.Validate(); !problems.empty()) {
    Error e = InvalidArgument(problems);
    e.message = "calibration store: refusing an invalid calibration: " + e.message;
    return e;
  }
  CalibrationReport stamped = report;
  if (stamped.created_unix_ms == 0) {
    stamped.created_unix_ms = std::chrono::duration_cast<std::chrono::milliseconds>(
                                  std::chrono::system_clock::now().time_since_epoch())
                                  .count();
  }
  Result<std::string> report_text = ReportToYaml(stamped);
  if (!report_text.ok()) return report_text.error();

  std::lock_guard<std::mutex> lock(mu_);
  const CalibrationId id{next_id_++};  // burnt even if writing fails: ids are never reused
  if (Status s = AtomicWriteFile(ReportPath(id), *report_text); !s.ok()) return s.error();
  if (Status s = geometry::SaveCalibrationYaml(calibration, CalibrationPath(id)); !s.ok()) {
    std::error_code ec;
    fs::remove(ReportPath(id), ec);  // our own incomplete entry; Open() would only warn about it
    Error e = s.error();
    if (e.code != ErrorCode::kInvalidArgument) e.code = ErrorCode::kInternal;
    return e;
  }
  entries_.push_back(Summarise(id, calibration, stamped));
  return id;
}

Status CalibrationStore::Activate(CalibrationId id) {
  std::lock_guard<std::mutex> lock(mu_);
  Result<StoredCalibration> stored = ReadLocked(id);
  if (!stored.ok()) return stored.error();
  if (!stored->report.passed) {
    std::string gates;
    for (const GateFailure& f : stored->report.failures) {
      if (!gates.empty()) gates += "; ";
      gates += f.message;
    }
    return FailedPrecondition(id.Name() + " failed its quality gates" +
                              (gates.empty() ? std::string() : " (" + gates + ")") +
                              "; it can be inspected but not activated");
  }
  const std::string active_path = (fs::path(directory_) / kActiveFile).string();
  if (Status s = AtomicWriteFile(active_path, id.Name() + "\n"); !s.ok()) return s;
  active_ = id;
  return Status::Ok();
}

std::optional<CalibrationId> CalibrationStore::ActiveId() const {
  std::lock_guard<std::mutex> lock(mu_);
  return active_;
}

Result<StoredCalibration> CalibrationStore::Active() const {
  std::lock_guard<std::mutex> lock(mu_);
  if (!active_) return FailedPrecondition("no active calibration in " + directory_);
  return ReadLocked(*active_);
}

}  // namespace stevi::calibration
