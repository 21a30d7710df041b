#include "tests/testing/chromium.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <iostream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "tests/testing/data.h"

namespace stevi::testing {
namespace {

using std::chrono::milliseconds;
using std::chrono::seconds;
using ::testing::AllOf;
using ::testing::Contains;
using ::testing::HasSubstr;
using ::testing::Not;

using Clock = std::chrono::steady_clock;

constexpr milliseconds kWait{10000};

// The page: a console error at once, the status turns "ready" after 300 ms, then an uncaught
// exception; a green background for the screenshot.
constexpr const char* kPage = R"(<!doctype html>
<html><head><title>stevi chromium test</title>
<style>html, body { margin: 0; background: rgb(20, 200, 60); }</style></head>
<body>
<div id="status">waiting</div>
<input id="name" value="">
<button id="button" onclick="window.clicks = (window.clicks || 0) + 1">press</button>
<script>
  console.log('page script runs');
  console.error('test error from the page', 42);
  document.getElementById('name').addEventListener('change',
      (e) => { document.body.dataset.changed = e.target.value; });
  document.getElementById('name').addEventListener('input',
      (e) => { document.body.dataset.input = e.target.value; });
  window.addEventListener('mousedown', (e) => { window.mouseAt = [e.clientX, e.clientY]; });
  setTimeout(() => {
    document.getElementById('status').textContent = 'ready';
    setTimeout(() => { window.threw = true; throw new Error('uncaught from a timer'); }, 0);
  }, 300);
</script>
</body></html>
)";

// A loopback HTTP/1.0 server on a thread: GET / answers kPage, GET /slow too but 500 ms late,
// anything else 404. One request per
// connection. Stops (bounded) on destruction.
class PageServer {
 public:
  PageServer() {
    listen_fd_ = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    address.sin_port = 0;
    socklen_t length = sizeof address;
    if (listen_fd_ < 0 || bind(listen_fd_, reinterpret_cast<sockaddr*>(&address), length) != 0 ||
        listen(listen_fd_, 16) != 0 ||
        getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&address), &length) != 0 ||
        pipe(wake_) != 0) {
      ADD_FAILURE() << "cannot start the page server";
      return;
    }
    port_ = ntohs(address.sin_port);
    thread_ = std::thread([this] { Serve(); });
  }
  ~PageServer() {
    if (thread_.joinable()) {
      const char byte = 1;
      EXPECT_EQ(write(wake_[1], &byte, 1), 1);
      thread_.join();
    }
    for (int fd : {listen_fd_, wake_[0], wake_[1]}) {
      if (fd >= 0) close(fd);
    }
  }
  std::string url(const std::string& path = "/") const {
    return "http://127.0.0.1:" + std::to_string(port_) + path;
  }
  int requests() const { return requests_.load(); }

 private:
  void Serve() {
    while (true) {
      pollfd fds[2] = {{wake_[0], POLLIN, 0}, {listen_fd_, POLLIN, 0}};
      if (poll(fds, 2, -1) < 0 || fds[0].revents != 0) return;
      const int fd = accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
      if (fd < 0) continue;
      Answer(fd);
      close(fd);
    }
  }
  void Answer(int fd) {
    std::string request;
    char chunk[4096];
    while (request.find("\r\n\r\n") == std::string::npos) {
      pollfd p = {fd, POLLIN, 0};
      if (poll(&p, 1, 5000) <= 0) return;
      const ssize_t n = read(fd, chunk, sizeof chunk);
      if (n <= 0) return;
      request.append(chunk, static_cast<size_t>(n));
    }
    ++requests_;
    if (request.rfind("GET /slow ", 0) == 0) {
      // Answers the page 500 ms late (or at once when the server stops).
      pollfd p = {wake_[0], POLLIN, 0};
      poll(&p, 1, 500);
    }
    const bool root = request.rfind("GET / ", 0) == 0 || request.rfind("GET /slow ", 0) == 0;
    const std::string body = root ? kPage : "not found";
    const std::string response = std::string(root ? "HTTP/1.0 200 OK" : "HTTP/1.0 404 Not Found") +
                                 "\r\nContent-Type: text/html; charset=utf-8\r\nContent-Length: " +
                                 std::to_string(body.size()) + "\r\nConnection: close\r\n\r\n" +
                                 body;
    size_t sent = 0;
    while (sent < response.size()) {
      const ssize_t n = send(fd, response.data() + sent, response.size() - sent, MSG_NOSIGNAL);
      if (n <= 0) return;
      sent += static_cast<size_t>(n);
    }
  }

  int listen_fd_ = -1;
  int wake_[2] = {-1, -1};
  int port_ = 0;
  std::atomic<int> requests_{0};
  std::thread thread_;
};

double MsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// The width and height in a PNG's IHDR chunk; {-1, -1} when the bytes are not a PNG.
std::pair<int, int> PngSize(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  std::string header(24, '\0');
  file.read(header.data(), 24);
  if (!file || header.compare(0, 8, "\x89PNG\r\n\x1a\n") != 0 || header.compare(12, 4, "IHDR") != 0)
    return {-1, -1};
  auto be32 = [&](size_t at) {
    return static_cast<int>((static_cast<uint32_t>(static_cast<uint8_t>(header[at])) << 24) |
                            (static_cast<uint32_t>(static_cast<uint8_t>(header[at + 1])) << 16) |
                            (static_cast<uint32_t>(static_cast<uint8_t>(header[at + 2])) << 8) |
                            static_cast<uint32_t>(static_cast<uint8_t>(header[at + 3])));
  };
  return {be32(16), be32(20)};
}

// A loopback port that was free a moment ago.
int ClosedPort() {
  const int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t length = sizeof address;
  EXPECT_EQ(bind(fd, reinterpret_cast<sockaddr*>(&address), length), 0);
  EXPECT_EQ(getsockname(fd, reinterpret_cast<sockaddr*>(&address), &length), 0);
  close(fd);
  return ntohs(address.sin_port);
}

// Processes still running (zombies excluded: init reaps them) that belong to the browser: in its
// process group, or naming its private directory (the crashpad handlers).
std::vector<std::string> LiveLeftovers(pid_t pgid, const std::string& private_dir) {
  std::vector<std::string> members;
  for (const auto& entry : std::filesystem::directory_iterator("/proc")) {
    std::ifstream file(entry.path() / "stat");
    std::string stat;
    if (!std::getline(file, stat)) continue;
    const size_t close_paren = stat.rfind(')');
    if (close_paren == std::string::npos) continue;
    std::istringstream fields(stat.substr(close_paren + 1));
    char state = 0;
    long ppid = 0, pgrp = 0;
    if (!(fields >> state >> ppid >> pgrp) || state == 'Z') continue;
    std::ifstream cmdline_file(entry.path() / "cmdline", std::ios::binary);
    const std::string cmdline((std::istreambuf_iterator<char>(cmdline_file)),
                              std::istreambuf_iterator<char>());
    if (pgrp == pgid || cmdline.find(private_dir) != std::string::npos) members.push_back(stat);
  }
  return members;
}

class BrowserTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (Browser::ChromiumPath().empty()) {
      GTEST_SKIP() << "headless Chromium is not available: no executable at "
                   << Browser::WantedChromium() << " (install chromium or set STEVI_CHROMIUM)";
    }
  }

  // Launches a browser on the test page, failing the test (with Chromium's reason) if it cannot.
  std::unique_ptr<Browser> LaunchOnPage(int width = 1400, int height = 1000) {
    std::string error;
    const auto start = Clock::now();
    std::unique_ptr<Browser> browser = Browser::Launch(&error, width, height);
    const double launch_ms = MsSince(start);
    EXPECT_NE(browser, nullptr) << error;
    if (browser == nullptr) return nullptr;
    const auto navigate_start = Clock::now();
    EXPECT_TRUE(browser->Navigate(server_.url(), kWait)) << browser->last_error();
    const double navigate_ms = MsSince(navigate_start);
    std::cout << "launch " << launch_ms << " ms, navigate " << navigate_ms << " ms\n";
    RecordProperty("launch_ms", std::to_string(static_cast<int>(launch_ms)));
    RecordProperty("navigate_ms", std::to_string(static_cast<int>(navigate_ms)));
    return browser;
  }

  PageServer server_;
};

TEST_F(BrowserTest, EvaluatesExpressionsAndReadsTheDom) {
  std::unique_ptr<Browser> browser = LaunchOnPage();
  ASSERT_NE(browser, nullptr);
  EXPECT_GE(server_.requests(), 1);

  Browser::Eval e = browser->Evaluate("6 * 7", kWait);
  ASSERT_TRUE(e.ok) << e.error;
  EXPECT_EQ(e.value, 42);
  e = browser->Evaluate("document.title", kWait);
  EXPECT_EQ(e.value, "stevi chromium test");
  e = browser->Evaluate("({a: [1, 'two', null], b: {c: true}})", kWait);
  EXPECT_EQ(e.value, nlohmann::json::parse(R"({"a": [1, "two", null], "b": {"c": true}})"));
  e = browser->Evaluate("[window.innerWidth, window.innerHeight, location.href]", kWait);
  EXPECT_EQ(e.value, nlohmann::json::array({1400, 1000, server_.url()}));
  // A promise is awaited.
  e = browser->Evaluate("new Promise((resolve) => setTimeout(() => resolve('later'), 20))", kWait);
  EXPECT_TRUE(e.ok) << e.error;
  EXPECT_EQ(e.value, "later");
  // undefined is null; values JSON cannot hold are their text.
  e = browser->Evaluate("undefined", kWait);
  EXPECT_TRUE(e.ok && e.value.is_null()) << e.value;
  e = browser->Evaluate("0 / 0", kWait);
  EXPECT_EQ(e.value, "NaN");
}

TEST_F(BrowserTest, ExceptionsAreErrors) {
  std::unique_ptr<Browser> browser = LaunchOnPage();
  ASSERT_NE(browser, nullptr);
  Browser::Eval e = browser->Evaluate("throw new Error('kaboom')", kWait);
  EXPECT_FALSE(e.ok);
  EXPECT_THAT(e.error, HasSubstr("Error: kaboom"));
  e = browser->Evaluate("Promise.reject(new TypeError('rejected here'))", kWait);
  EXPECT_FALSE(e.ok);
  EXPECT_THAT(e.error, HasSubstr("TypeError: rejected here"));
  e = browser->Evaluate("1 +", kWait);
  EXPECT_FALSE(e.ok);
  EXPECT_THAT(e.error, HasSubstr("SyntaxError"));
  e = browser->Evaluate("document.querySelector('#nothing').textContent", kWait);
  EXPECT_FALSE(e.ok);
  EXPECT_THAT(e.error, HasSubstr("TypeError"));
  EXPECT_EQ(browser->last_error(), e.error);
  // Reported by Evaluate, not as page errors.
  EXPECT_THAT(browser->ConsoleErrors(), Not(Contains(HasSubstr("kaboom"))));
  // The browser still works.
  e = browser->Evaluate("1 + 1", kWait);
  EXPECT_TRUE(e.ok) << e.error;
  EXPECT_EQ(e.value, 2);
}

TEST_F(BrowserTest, WaitForFollowsThePageTimerAndTimesOut) {
  std::unique_ptr<Browser> browser = LaunchOnPage();
  ASSERT_NE(browser, nullptr);
  const auto start = Clock::now();
  ASSERT_TRUE(browser->WaitFor("document.getElementById('status').textContent === 'ready'", kWait))
      << browser->last_error();
  // The page's timer fires 300 ms after its script ran; nothing waits much longer than that.
  EXPECT_LT(MsSince(start), 2000);
  EXPECT_EQ(browser->Evaluate("document.getElementById('status').textContent", kWait).value,
            "ready");

  const auto timeout_start = Clock::now();
  EXPECT_FALSE(
      browser->WaitFor("document.title === 'never' // a trailing comment", milliseconds(300)));
  const double waited_ms = MsSince(timeout_start);
  EXPECT_GE(waited_ms, 290);
  EXPECT_LT(waited_ms, 2000);
  EXPECT_THAT(browser->last_error(), HasSubstr("still false after 300 ms"));
  // A throwing condition is "not yet", and its exception is reported on timeout.
  EXPECT_FALSE(
      browser->WaitFor("document.querySelector('#later').textContent === 'x'", milliseconds(100)));
  EXPECT_THAT(browser->last_error(), HasSubstr("TypeError"));
  // An element that appears later.
  ASSERT_TRUE(browser
                  ->Evaluate("setTimeout(() => { const d = document.createElement('p'); d.id = "
                             "'later'; d.textContent = 'x'; document.body.append(d); }, 100)",
                             kWait)
                  .ok);
  EXPECT_TRUE(browser->WaitFor("document.querySelector('#later').textContent === 'x'", kWait))
      << browser->last_error();
}

TEST_F(BrowserTest, ConsoleErrorsHoldLoggedErrorsAndUncaughtExceptions) {
  std::unique_ptr<Browser> browser = LaunchOnPage();
  ASSERT_NE(browser, nullptr);
  ASSERT_TRUE(browser->WaitFor("window.threw === true", kWait)) << browser->last_error();
  // The exception event follows the throw; give it a round trip to arrive.
  ASSERT_TRUE(browser->Evaluate("new Promise((r) => setTimeout(r, 50))", kWait).ok);
  const std::vector<std::string> errors = browser->ConsoleErrors();
  EXPECT_THAT(errors, Contains("console.error: test error from the page 42"));
  EXPECT_THAT(errors,
              Contains(AllOf(HasSubstr("uncaught: "), HasSubstr("Error: uncaught from a timer"),
                             HasSubstr(server_.url()))));
  // Nothing else: in particular not the 404 of the browser's own /favicon.ico request.
  EXPECT_EQ(errors.size(), 2u) << ::testing::PrintToString(errors);
  EXPECT_THAT(browser->ConsoleMessages(), Contains("log: page script runs"));
  EXPECT_THAT(errors, Not(Contains(HasSubstr("page script runs"))));
  // A failed resource load is an error too.
  ASSERT_TRUE(browser
                  ->Evaluate("new Promise((resolve) => { const i = new Image(); i.onerror = "
                             "resolve; i.src = '/missing.png'; })",
                             kWait)
                  .ok);
  ASSERT_TRUE(browser->Evaluate("new Promise((r) => setTimeout(r, 50))", kWait).ok);
  EXPECT_THAT(browser->ConsoleErrors(),
              Contains(AllOf(HasSubstr("404"), HasSubstr("/missing.png"))))
      << ::testing::PrintToString(browser->ConsoleErrors());
}

TEST_F(BrowserTest, ScreenshotIsAPngOfTheViewport) {
  std::unique_ptr<Browser> browser = LaunchOnPage(800, 600);
  ASSERT_NE(browser, nullptr);
  const std::string path = MakeTempDir("stevi-chromium-test") + "/shot.png";
  ASSERT_TRUE(browser->Screenshot(path)) << browser->last_error();
  EXPECT_EQ(PngSize(path), std::make_pair(800, 600));
  const cv::Mat image = cv::imread(path, cv::IMREAD_COLOR);
  ASSERT_FALSE(image.empty());
  EXPECT_EQ(image.cols, 800);
  EXPECT_EQ(image.rows, 600);
  // The page background, away from the text (BGR).
  const cv::Vec3b pixel = image.at<cv::Vec3b>(500, 700);
  EXPECT_NEAR(pixel[0], 60, 2);
  EXPECT_NEAR(pixel[1], 200, 2);
  EXPECT_NEAR(pixel[2], 20, 2);
  std::filesystem::remove_all(std::filesystem::path(path).parent_path());
}

TEST_F(BrowserTest, ClickSetValueAndMouse) {
  std::unique_ptr<Browser> browser = LaunchOnPage();
  ASSERT_NE(browser, nullptr);
  ASSERT_TRUE(browser->Click("#button")) << browser->last_error();
  ASSERT_TRUE(browser->Click("#button")) << browser->last_error();
  EXPECT_EQ(browser->Evaluate("window.clicks", kWait).value, 2);
  ASSERT_TRUE(browser->SetValue("#name", "a \"quoted\" 'value'")) << browser->last_error();
  EXPECT_EQ(browser->Evaluate("document.body.dataset.changed", kWait).value,
            "a \"quoted\" 'value'");
  EXPECT_EQ(browser->Evaluate("document.body.dataset.input", kWait).value, "a \"quoted\" 'value'");
  EXPECT_FALSE(browser->Click("#missing"));
  EXPECT_THAT(browser->last_error(), HasSubstr("no element matches #missing"));
  ASSERT_TRUE(browser->ClickAt(321, 456)) << browser->last_error();
  EXPECT_EQ(browser->Evaluate("window.mouseAt", kWait).value, nlohmann::json::array({321, 456}));
}

TEST_F(BrowserTest, NavigatesToDataUrlsAndReportsUnreachablePages) {
  std::string error;
  std::unique_ptr<Browser> browser = Browser::Launch(&error);
  ASSERT_NE(browser, nullptr) << error;
  ASSERT_TRUE(browser->Navigate("data:text/html,<title>inline</title><p id=p>hello</p>", kWait))
      << browser->last_error();
  EXPECT_EQ(
      browser->Evaluate("document.title + ' ' + document.getElementById('p').textContent", kWait)
          .value,
      "inline hello");
  // A loopback port nothing listens on (Chromium refuses "unsafe" ports such as 1 with
  // net::ERR_UNSAFE_PORT before trying).
  EXPECT_FALSE(browser->Navigate("http://127.0.0.1:" + std::to_string(ClosedPort()) + "/", kWait));
  EXPECT_THAT(browser->last_error(), HasSubstr("ERR_CONNECTION_REFUSED"));
  // Navigate waits for the load of the document it asked for, however late.
  const auto slow_start = Clock::now();
  ASSERT_TRUE(browser->Navigate(server_.url("/slow"), kWait)) << browser->last_error();
  EXPECT_GE(MsSince(slow_start), 490);
  EXPECT_EQ(
      browser->Evaluate("[document.readyState, document.title, location.pathname]", kWait).value,
      nlohmann::json::array({"complete", "stevi chromium test", "/slow"}));
  // A page that is served with 404 still loads.
  EXPECT_TRUE(browser->Navigate(server_.url("/nothing"), kWait)) << browser->last_error();
  EXPECT_EQ(browser->Evaluate("document.body.textContent", kWait).value, "not found");
}

TEST_F(BrowserTest, ADeadBrowserFailsFastWithAClearError) {
  std::string error;
  std::unique_ptr<Browser> browser = Browser::Launch(&error);
  ASSERT_NE(browser, nullptr) << error;
  const std::string profile = browser->user_data_dir();
  const pid_t pid = browser->pid();
  EXPECT_TRUE(std::filesystem::is_directory(profile));
  ASSERT_EQ(kill(browser->pid(), SIGKILL), 0);
  const auto start = Clock::now();
  const Browser::Eval e = browser->Evaluate("1", seconds(30));
  EXPECT_FALSE(e.ok);
  EXPECT_THAT(e.error, HasSubstr("chromium closed its DevTools pipe"));
  EXPECT_THAT(e.error, HasSubstr("killed by signal 9"));
  EXPECT_LT(MsSince(start), 5000);
  EXPECT_FALSE(browser->Navigate("about:blank", seconds(30)));
  EXPECT_THAT(browser->last_error(), HasSubstr("chromium closed its DevTools pipe"));
  const auto close_start = Clock::now();
  browser.reset();
  EXPECT_LT(MsSince(close_start), 5000);
  EXPECT_FALSE(std::filesystem::exists(profile));
  EXPECT_THAT(LiveLeftovers(pid, profile), ::testing::IsEmpty());
}

TEST_F(BrowserTest, CloseIsPromptAndRemovesTheProfile) {
  std::string error;
  std::unique_ptr<Browser> browser = Browser::Launch(&error);
  ASSERT_NE(browser, nullptr) << error;
  const std::string profile = browser->user_data_dir();
  const pid_t pid = browser->pid();
  const auto start = Clock::now();
  browser.reset();
  const double close_ms = MsSince(start);
  std::cout << "close " << close_ms << " ms\n";
  EXPECT_LT(close_ms, 3000);
  EXPECT_FALSE(std::filesystem::exists(profile));
  // No process of the browser's group is left running (renderers, zygotes, GPU process).
  EXPECT_THAT(LiveLeftovers(pid, profile), ::testing::IsEmpty());
}

TEST(BrowserLaunch, AMissingBinaryIsAClearError) {
  const char* old = std::getenv("STEVI_CHROMIUM");
  const std::string saved = old != nullptr ? old : "";
  setenv("STEVI_CHROMIUM", "/nonexistent/chromium", 1);
  std::string error;
  EXPECT_EQ(Browser::Launch(&error), nullptr);
  EXPECT_THAT(error, HasSubstr("/nonexistent/chromium"));
  EXPECT_EQ(Browser::ChromiumPath(), "");
  if (old != nullptr) {
    setenv("STEVI_CHROMIUM", saved.c_str(), 1);
  } else {
    unsetenv("STEVI_CHROMIUM");
  }
}

}  // namespace
}  // namespace stevi::testing
