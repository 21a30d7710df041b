// Edits a stevi.v1.PipelineConfig by dotted field path, for `stevi config set KEY=VALUE`.
#pragma once

#include <string>

#include <google/protobuf/message.h>

namespace stevi::client {

// Sets the field at `path` ("algorithm", "matcher.kind", "canonical.threshold_range_m") of
// `message` from text. Enum values may be given in full ("ALGORITHM_STEVIS") or by their suffix,
// case-insensitive ("stevis", "semi_global"). Returns "" on success, else a one-line problem naming
// the key (unknown field, with the valid ones listed; a value of the wrong type).
std::string SetFieldByPath(google::protobuf::Message& message, const std::string& path,
                           const std::string& value);

}  // namespace stevi::client
