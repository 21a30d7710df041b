// Writing a file so that readers see the old contents or the new, never a torn one.
#pragma once

#include <string>

#include "core/common/error.h"

namespace stevi {

// Writes `text` to `path` atomically: a temporary file beside it, fsync, rename, fsync of the
// directory. On failure the file is left as it was and the error names the path and the step.
Status AtomicWriteFile(const std::string& path, const std::string& text);

}  // namespace stevi
