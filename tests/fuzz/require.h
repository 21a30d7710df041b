// The fuzz targets' invariant check: what a target asserts besides the sanitizers.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <source_location>

namespace stevi::fuzz {

// A broken invariant: says which (the caller's file and line), then aborts (the fuzzer keeps the
// input).
inline void Require(bool ok, std::source_location where = std::source_location::current()) {
  if (ok) return;
  std::fprintf(stderr, "invariant broken at %s:%u\n", where.file_name(),
               static_cast<unsigned>(where.line()));
  std::abort();
}

}  // namespace stevi::fuzz
