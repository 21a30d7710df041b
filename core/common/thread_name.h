#pragma once

#include <string_view>

namespace stevi {

// Names the calling thread, as `ps -L`, `top -H`, gdb and /proc/PID/task/TID/comm show it, so
// that stevi's threads can be told from its libraries' (gRPC's "grpc_global_tim",
// "event_engine", GLib's "gmain"). Linux keeps 15 bytes; a longer name is cut. stevi's names
// start with "stevi-". A new thread inherits its creator's name until it sets its own: a
// library's unnamed helper started from one of ours carries our name (and one started from the
// main thread the program's).
void NameThisThread(std::string_view name);

}  // namespace stevi
