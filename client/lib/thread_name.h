// Names the calling thread for ps -L, top -H, gdb and /proc/PID/task/TID/comm, so that stevi's
// threads can be told from gRPC's and civetweb's. The client's own copy of core's
// NameThisThread: client/ depends on the proto API only. Linux keeps 15 bytes of `name`.
#pragma once

#include <pthread.h>

namespace stevi::client {

inline void NameThisThread(const char* name) { pthread_setname_np(pthread_self(), name); }

}  // namespace stevi::client
