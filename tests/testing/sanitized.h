// Whether this test build runs under a sanitizer (deploy/sanitize.sh). Instrumented code runs 2-15
// times slower, so a test whose source outruns the pipeline sees more frames dropped there.
#pragma once

namespace stevi::testing {

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
inline constexpr bool kSanitized = true;
#else
inline constexpr bool kSanitized = false;
#endif

}  // namespace stevi::testing
