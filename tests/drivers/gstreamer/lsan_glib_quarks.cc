// Linked into the GStreamer tests: under AddressSanitizer, LeakSanitizer ignores the one block
// GLib drops by design, and only that.
//
// GLib allocates its first quark table (2048 pointers, 16 KiB) in its library constructor. When a
// process makes more than 2048 quarks, as loading GStreamer's plugins does, GLib replaces the
// table by a larger copy and never frees the old one (its lookups are lock-free), so LeakSanitizer
// reports 16384 bytes "leaked". Debian's GLib has no frame pointers: with the default fast
// unwinder the report's stack ends in g_malloc, and only a suppression of all of GLib would match
// it, which would hide the leaks of GStreamer objects (all allocated by GLib) that these tests
// must catch. So these tests unwind allocations fully (their stacks then reach the loader) and
// suppress the allocations made while a library is being loaded (_dl_init), which stevi code
// never does. (A deploy/sanitizers/lsan.supp entry could not be as narrow: the stack there is
// the fast unwinder's.)
#if defined(__SANITIZE_ADDRESS__)
extern "C" const char* __asan_default_options() { return "fast_unwind_on_malloc=0"; }
extern "C" const char* __lsan_default_suppressions() { return "leak:_dl_init\n"; }
#endif
