// glibc's allocator, set for the long-running commands (the station, the MAVLink bridge). Without
// glibc, both do nothing.
#pragma once

namespace stevi::client::commands {

// Caps glibc's malloc arenas at two for the whole process. glibc gives threads up to eight arenas
// per core, and each keeps the holes its threads' freed blocks leave. A command with many threads
// that each allocate little (the station's 47: gRPC's, civetweb's, its streams') keeps growing
// from those holes although its heap does not: in a soak, heaptrack measured the station's heap
// at a 3.3 MB peak, while its resident memory grew 17 % in 7 minutes with glibc's default arenas
// and 1 % with two. Call once, first thing in main(), before any thread starts.
void ShareMallocArenas();

// Hands the free pages of every arena back to the kernel (malloc_trim). After a burst, such as a
// viewer's queue of preview images filling up and draining, the freed memory otherwise stays
// resident for the life of the process. The station calls it every 10 s, from its main thread,
// which does nothing else.
void ReturnFreeMemory();

}  // namespace stevi::client::commands
