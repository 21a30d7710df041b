// GStreamer peers for tests: a video file written by a real pipeline, and a real RTSP server on
// loopback. For the GStreamer source's tests (drivers/gstreamer) and the server's.
#pragma once

#include <functional>
#include <string>
#include <thread>
#include <vector>

#include <gst/rtsp-server/rtsp-server.h>
#include <opencv2/core.hpp>

namespace stevi::testing {

// Writes `frames` (CV_8UC1, one size) as a video at `fps` through appsrc ! ENCODING ! filesink,
// rows padded to GStreamer's GRAY8 stride (a multiple of 4), then waits for the muxer's end of
// stream. Fails the test (ASSERT) on error: call with ASSERT_NO_FATAL_FAILURE.
//   WriteVideo: any `encoding` (the elements between the GRAY8 appsrc and the filesink).
//   WriteMjpegAvi: Motion-JPEG in AVI (jpegenc ! avimux), lossy, as a UVC camera's MJPEG mode.
//   WriteRawMkv: uncompressed GRAY8 in Matroska (matroskamux), lossless: the frames come back
//   bit for bit.
void WriteVideo(const std::string& path, const std::vector<cv::Mat>& frames, int fps,
                const std::string& encoding);
void WriteMjpegAvi(const std::string& path, const std::vector<cv::Mat>& frames, int fps,
                   int quality = 95);
void WriteRawMkv(const std::string& path, const std::vector<cv::Mat>& frames, int fps);

// A gst-rtsp-server on 127.0.0.1 serving one stream at rtsp://127.0.0.1:PORT/stereo, run by its
// own thread and GMainContext. `launch` is the media's pipeline, in parentheses, its payloader
// named pay0 ("( videotestsrc is-live=true ! ... ! jpegenc ! rtpjpegpay name=pay0 pt=26 )").
// Serve() and Stop() run on that thread and return once done.
class LoopbackRtspServer {
 public:
  explicit LoopbackRtspServer(const std::string& launch);
  ~LoopbackRtspServer();
  LoopbackRtspServer(const LoopbackRtspServer&) = delete;
  LoopbackRtspServer& operator=(const LoopbackRtspServer&) = delete;

  // Listens (again: on the port of the first time) and returns the port; -1 on failure.
  int Serve();
  // Closes every client's connection, then the listening socket.
  void Stop();

 private:
  // Runs `work` on the server's thread and waits for it.
  void RunOnLoop(std::function<void()> work);

  GMainContext* context_ = nullptr;
  GMainLoop* loop_ = nullptr;
  GstRTSPServer* server_ = nullptr;
  GSource* source_ = nullptr;  // the listening socket's, while serving
  std::thread thread_;
};

}  // namespace stevi::testing
