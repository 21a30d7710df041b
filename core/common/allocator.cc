#include "core/common/allocator.h"

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace stevi {

void KeepFrameMemory() {
#if defined(__GLIBC__)
  // Allocations below 32 MiB (glibc's largest threshold) come from the heap, not from mmap: a
  // fixed threshold also turns off glibc's adaptive one, which the order buffers are freed in
  // can defeat. Free memory at the top of a heap is kept up to 256 MiB rather than trimmed.
  mallopt(M_MMAP_THRESHOLD, 32 << 20);
  mallopt(M_TRIM_THRESHOLD, 256 << 20);
#endif
}

}  // namespace stevi
