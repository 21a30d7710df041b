// Process-wide allocator settings for a program that processes frames.
#pragma once

namespace stevi {

// Keeps freed memory in the process instead of handing it back to the kernel and faulting it in
// again on the next frame. Each frame allocates and frees buffers of about a megabyte (a
// disparity map, labels, masks, OpenCV's temporaries). With glibc's defaults those are mapped,
// unmapped and the pages faulted in anew every frame (about 600 page faults a frame, 11 % of
// the CPU of the detection stages). Holds memory up to the peak a frame needs; no effect on other
// C libraries. Call once, first thing in main(), before any thread starts.
void KeepFrameMemory();

}  // namespace stevi
