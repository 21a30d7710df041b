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

}  // namespace

std::string_view AlgorithmName(Algorithm algorithm) {
  return fields::NameOf(algorithm, std::span<const fields::ChoiceName<Algorithm>>(
                                       PipelineConfig::kAlgorithmNames))
      .value_or("unknown");
}

std::optional<Algorithm> AlgorithmFromName(std::string_view name) {
  for (const fields::ChoiceName<Algorithm>& n : PipelineConfig::kAlgorithmNames) {
    if (EqualsIgnoreCase(name, n.name)) return n.value;
  }
  return std::nullopt;
}

PipelineConfig ConfigForAlgorithm(Algorithm algorithm) {
  PipelineConfig config;
  config.algorithm = algorithm;
  if (algorithm == Algorithm::kStixels) config.matcher.kind = stereo::MatcherKind::kDense;
  return config;
}

std::vector<std::string> ApplySettings(PipelineConfig& config,
                                       const std::vector<std::string>& settings) {
  PipelineConfig next = config;
  std::vector<std::string> problems;
  for (const std::string& setting : settings) {
    const size_t eq = setting.find('=');
    if (eq == std::string::npos) {
      problems.push_back("'" + setting + "': expected path=value");
      continue;
    }
    std::optional<std::string> problem = fields::Assign(
        next, std::string_view(setting).substr(0, eq), std::string_view(setting).substr(eq + 1));
    if (problem) problems.push_back(std::move(*problem));
  }
  if (problems.empty()) problems = next.Validate();
  if (problems.empty()) config = std::move(next);
  return problems;
}

// Every stage's options are validated, whichever algorithm runs (the matcher's: the selected
// kind's only, MatcherOptions::Validate()).
std::vector<std::string> PipelineConfig::Validate() const { return fields::Check(*this); }

ConfigStore::ConfigStore(PipelineConfig initial)
    : active_(std::make_shared<const PipelineConfig>(std::move(initial))) {}

std::shared_ptr<const PipelineConfig> ConfigStore::Get() const {
  std::lock_guard lock(mu_);
  return active_;
}

Result<std::shared_ptr<const PipelineConfig>> ConfigStore::Set(PipelineConfig config) {
  const std::vector<std::string> problems = config.Validate();
  if (!problems.empty()) return InvalidArgument(problems);
  auto snapshot = std::make_shared<const PipelineConfig>(std::move(config));
  std::lock_guard lock(mu_);
  active_ = snapshot;
  return snapshot;
}

}  // namespace stevi::pipeline
