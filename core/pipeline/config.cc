#include "core/pipeline/config.h"

#include "core/common/error.h"

#include <cctype>
#include <string>
#include <utility>

namespace stevi::pipeline {
namespace {

bool EqualsIgnoreCase(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i) {
    if (std::tolower(static_cast<unsigned char>(a[i])) !=
        std::tolower(static_cast<unsigned char>(b[i]))) {
      return false;
    }
  }
  return true;
}

constexpr Algorithm kAlgorithms[] = {Algorithm::kCanonical, Algorithm::kSteViE, Algorithm::kSteViS};

}  // namespace

std::string_view AlgorithmName(Algorithm algorithm) {
  switch (algorithm) {
    case Algorithm::kCanonical: return "canonical";
    case Algorithm::kSteViE: return "stevie";
    case Algorithm::kSteViS: return "stevis";
  }
  return "unknown";
}

std::optional<Algorithm> AlgorithmFromName(std::string_view name) {
  for (Algorithm a : kAlgorithms) {
    if (EqualsIgnoreCase(name, AlgorithmName(a))) return a;
  }
  return std::nullopt;
}

std::vector<std::string> PipelineConfig::Validate() const {
  std::vector<std::string> problems;
  switch (algorithm) {
    case Algorithm::kCanonical:
    case Algorithm::kSteViE:
    case Algorithm::kSteViS: break;
    default:
      problems.push_back("algorithm: unknown value " + std::to_string(static_cast<int>(algorithm)));
  }
  if (max_width_px != 0 && (max_width_px < 64 || max_width_px > 16384)) {
    problems.push_back("max_width_px: must be 0 (never bin) or in 64..16384, got " +
                       std::to_string(max_width_px));
  }
  AppendPrefixed(problems, "matcher.", matcher.Validate());
  AppendPrefixed(problems, "range.", range.Validate());
  AppendPrefixed(problems, "canonical.", canonical.Validate());
  AppendPrefixed(problems, "stevie.", stevie.Validate());
  AppendPrefixed(problems, "stevis.", stevis.Validate());
  AppendPrefixed(problems, "tracking.", tracking.Validate());
  AppendPrefixed(problems, "mount.", mount.Validate());
  return problems;
}

ConfigStore::ConfigStore(PipelineConfig initial)
    : active_(std::make_shared<const PipelineConfig>(std::move(initial))) {}

std::shared_ptr<const PipelineConfig> ConfigStore::Get() const {
  std::lock_guard lock(mu_);
  return active_;
}

Result<std::shared_ptr<const PipelineConfig>> ConfigStore::Set(PipelineConfig config) {
  const std::vector<std::string> problems = config.Validate();
  if (!problems.empty()) return Error::Invalid(problems);
  auto snapshot = std::make_shared<const PipelineConfig>(std::move(config));
  std::lock_guard lock(mu_);
  active_ = snapshot;
  return snapshot;
}

}  // namespace stevi::pipeline
