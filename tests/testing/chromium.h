// Headless Chromium for browser tests, driven over the DevTools protocol on
// --remote-debugging-pipe (JSON messages, each ended by a NUL byte; Chromium reads fd 3 and writes
// fd 4). One browser process, one page (a tab attached with a flat session).
#pragma once

#include <sys/types.h>

#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace stevi::testing {

// Thread-compatible: call a Browser from one thread at a time. Every call is bounded by its
// timeout, and fails at once (with Chromium's stderr in the error) if Chromium has died.
class Browser {
 public:
  // The Chromium binary used: $STEVI_CHROMIUM if set, else /usr/bin/chromium; "" when that is not
  // an executable file (tests then GTEST_SKIP, naming WantedChromium()).
  static std::string ChromiumPath();
  static std::string WantedChromium();

  // Launches Chromium headless (--no-sandbox, a fresh temporary --user-data-dir removed by the
  // destructor, a viewport of width x height CSS pixels at scale 1) and opens one blank page.
  // nullptr with *error set when Chromium is absent or does not start within 30 s.
  static std::unique_ptr<Browser> Launch(std::string* error, int width = 1400, int height = 1000);
  // Closes the browser (Browser.close), then kills what is left of its process group; bounded
  // (about 5 s at worst). Removes the user data directory.
  ~Browser();
  Browser(const Browser&) = delete;
  Browser& operator=(const Browser&) = delete;

  // Navigates the page and waits for its load event. False on a network error (e.g.
  // net::ERR_CONNECTION_REFUSED), a timeout or a dead browser; the reason is in last_error().
  // An HTTP error page still loads (true).
  bool Navigate(const std::string& url, std::chrono::milliseconds timeout);

  // Runtime.evaluate with returnByValue and awaitPromise: `value` is the JSON of the result (null
  // for undefined; NaN/Infinity/-0/bigint as their text). A thrown exception or a rejected promise
  // gives ok = false with the exception's text (message and stack) in `error`.
  struct Eval {
    bool ok = false;
    nlohmann::json value;
    std::string error;
  };
  Eval Evaluate(const std::string& expression, std::chrono::milliseconds timeout);

  // Waits until the JS boolean expression `condition` is truthy: a promise in the page re-checks it
  // every 10 ms (setTimeout) with the timeout enforced in JS, so nothing sleeps in C++. A condition
  // that throws counts as false (e.g. an element not there yet). False on timeout; last_error()
  // then names the condition and its last exception.
  bool WaitFor(const std::string& condition, std::chrono::milliseconds timeout);

  // Page.captureScreenshot of the viewport (width x height pixels) to a PNG file.
  bool Screenshot(const std::string& png_path,
                  std::chrono::milliseconds timeout = std::chrono::seconds(10));

  // Errors seen so far, oldest first: console.error/console.assert calls ("console.error: text"),
  // uncaught exceptions and unhandled rejections ("uncaught: Error: text\n    at ..."), and
  // browser log errors such as failed resource loads ("log.network: Failed to load resource: the
  // server responded with a status of 404 (Not Found) http://...").
  std::vector<std::string> ConsoleErrors() const;
  // Every console API call so far ("log: text", "warning: text", "error: text", ...).
  std::vector<std::string> ConsoleMessages() const;

  // Helpers on top of Evaluate; false (with last_error()) when no element matches `selector`
  // (document.querySelector syntax).
  // element.click() (a synthetic click: fires click handlers, toggles checkboxes, submits).
  bool Click(const std::string& selector,
             std::chrono::milliseconds timeout = std::chrono::seconds(10));
  // Sets element.value and dispatches bubbling "input" and "change" events, as typing would.
  bool SetValue(const std::string& selector, const std::string& value,
                std::chrono::milliseconds timeout = std::chrono::seconds(10));
  // A real left click at viewport coordinates (CSS pixels) through Input.dispatchMouseEvent, for
  // widgets that listen to mousedown/mouseup (e.g. a Leaflet map).
  bool ClickAt(double x, double y, std::chrono::milliseconds timeout = std::chrono::seconds(10));

  // Any DevTools command on the page's session (e.g. "Emulation.setGeolocationOverride");
  // `value` is the command's result object, `error` the protocol error.
  Eval Command(const std::string& method, const nlohmann::json& params,
               std::chrono::milliseconds timeout);

  // Why the last failing call failed.
  const std::string& last_error() const { return last_error_; }
  // Chromium's stderr so far (bounded to its last MiB).
  std::string Stderr() const;
  // The browser's main process (a process group leader); for tests of the driver itself.
  pid_t pid() const;
  const std::string& user_data_dir() const;

 private:
  struct Impl;
  explicit Browser(std::unique_ptr<Impl> impl);
  bool Fail(std::string error);

  std::unique_ptr<Impl> impl_;
  std::string last_error_;
};

}  // namespace stevi::testing
