// The `stevi` process's stop signals: SIGINT and SIGTERM end a streaming command cleanly (its
// stream cancelled, its threads joined) instead of killing the process.
#pragma once

#include <functional>

namespace stevi::client::commands {

// Blocks SIGINT and SIGTERM in every thread (call it first in main(), before any thread starts:
// gRPC's threads inherit the mask) and waits for them on a thread of its own. The first signal
// calls the handler set by OnStopSignal (a streaming command ends its stream and exits cleanly);
// with none set, or at a second signal, the process exits with 128 + the signal number.
void HandleStopSignals();
// Sets the handler (nullptr: none). Waits first for a handler that is running to return, so that
// after OnStopSignal(nullptr) nothing refers to what the old handler captured.
void OnStopSignal(std::function<void()> handler);

}  // namespace stevi::client::commands
