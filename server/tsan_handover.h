// Happens-before marks for ThreadSanitizer where a hand-over between threads goes through code
// it cannot see. gRPC starts a reactor on one thread and calls its callbacks (OnWriteDone,
// OnReadDone, OnCancel, OnDone) on its own, through its completion queue, which Debian builds
// without TSan. gRPC guarantees that order; these marks tell TSan about it. No-ops in other builds.
#pragma once

#if defined(__SANITIZE_THREAD__)
extern "C" void __tsan_acquire(void* addr);
extern "C" void __tsan_release(void* addr);
#endif

namespace stevi::server {
namespace internal {
inline char calls_ended;  // only its address is used
}  // namespace internal

// What this thread did so far happens before a later TakeOver(object) on any thread. Call it once
// the object is ready and before the operation whose callback will take it over.
inline void HandOver([[maybe_unused]] const void* object) {
#if defined(__SANITIZE_THREAD__)
  __tsan_release(const_cast<void*>(object));
#endif
}

// First thing in a callback: everything before the matching HandOver(object) happened before.
inline void TakeOver([[maybe_unused]] const void* object) {
#if defined(__SANITIZE_THREAD__)
  __tsan_acquire(const_cast<void*>(object));
#endif
}

// A reactor callback's whole body, for TSan: takes the object over on entry and hands it over
// on exit, after the body's locks are released. gRPC calls the next callback, OnDone among
// them, only after this one returned, but through its own executor, so without the mark at
// the exit OnDone's delete would look unordered with this callback's last unlock. The first
// statement of OnReadDone, OnWriteDone and OnCancel.
class CallbackScope {
 public:
  explicit CallbackScope(const void* object) : object_(object) { TakeOver(object_); }
  ~CallbackScope() { HandOver(object_); }
  CallbackScope(const CallbackScope&) = delete;
  CallbackScope& operator=(const CallbackScope&) = delete;

 private:
  const void* object_;
};

// The end of a call's OnDone, handed over to the thread that shuts the server down: gRPC's
// Server::Shutdown() returns only after every call's OnDone has returned (it counts them in
// its own, uninstrumented, code), and the services are destroyed after it. Last thing in each
// reactor's OnDone, before it deletes itself.
inline void CallEnded() { HandOver(&internal::calls_ended); }
// After grpc::Server::Shutdown() and Wait(): every OnDone happened before.
inline void AllCallsEnded() { TakeOver(&internal::calls_ended); }

}  // namespace stevi::server
