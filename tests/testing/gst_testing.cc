#include "tests/testing/gst_testing.h"

#include <gst/app/gstappsrc.h>
#include <gst/gst.h>
#include <gtest/gtest.h>

#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <mutex>

#include "drivers/gstreamer/gst_capture.h"
#include "drivers/gstreamer/gst_ptr.h"
#include "drivers/gstreamer/pipelines.h"

namespace stevi::testing {
namespace {

#if defined(__SANITIZE_THREAD__)
extern "C" void __tsan_acquire(void* addr);
extern "C" void __tsan_release(void* addr);
#endif

// Happens-before marks for ThreadSanitizer across a hand-over it cannot see (GLib's main context):
// what this thread did before HandOver(p) happens before a TakeOver(p) on another. No-ops in
// other builds.
void HandOver([[maybe_unused]] void* p) {
#if defined(__SANITIZE_THREAD__)
  __tsan_release(p);
#endif
}
void TakeOver([[maybe_unused]] void* p) {
#if defined(__SANITIZE_THREAD__)
  __tsan_acquire(p);
#endif
}

}  // namespace

void WriteVideo(const std::string& path, const std::vector<cv::Mat>& frames, int fps,
                const std::string& encoding) {
  ASSERT_FALSE(frames.empty());
  drivers::InitGStreamer();
  const cv::Size size = frames[0].size();
  Result<std::string> location = drivers::QuoteGstValue(path, "path");
  ASSERT_TRUE(location.ok()) << location.error().message;
  const std::string description =
      "appsrc name=src format=time caps=video/x-raw,format=GRAY8,width=" +
      std::to_string(size.width) + ",height=" + std::to_string(size.height) +
      ",framerate=" + std::to_string(fps) + "/1 ! " + encoding +
      " ! filesink location=" + location.value();
  GError* raw_error = nullptr;
  drivers::gst::ElementPtr pipeline = drivers::gst::AdoptFloating(
      gst_parse_launch_full(description.c_str(), nullptr, GST_PARSE_FLAG_FATAL_ERRORS, &raw_error));
  const drivers::gst::ErrorPtr error(raw_error);
  ASSERT_FALSE(error) << error->message;
  drivers::gst::ElementPtr src(gst_bin_get_by_name(GST_BIN(pipeline.get()), "src"));
  ASSERT_NE(gst_element_set_state(pipeline.get(), GST_STATE_PLAYING), GST_STATE_CHANGE_FAILURE);
  const int stride = (size.width + 3) / 4 * 4;
  for (size_t k = 0; k < frames.size(); ++k) {
    GstBuffer* buffer =
        gst_buffer_new_allocate(nullptr, static_cast<gsize>(stride) * size.height, nullptr);
    GstMapInfo map;
    ASSERT_TRUE(gst_buffer_map(buffer, &map, GST_MAP_WRITE));
    for (int y = 0; y < size.height; ++y) {
      std::memcpy(map.data + static_cast<size_t>(y) * stride, frames[k].ptr(y),
                  static_cast<size_t>(size.width));
    }
    gst_buffer_unmap(buffer, &map);
    GST_BUFFER_PTS(buffer) = gst_util_uint64_scale(k, GST_SECOND, static_cast<guint64>(fps));
    GST_BUFFER_DURATION(buffer) = gst_util_uint64_scale(1, GST_SECOND, static_cast<guint64>(fps));
    ASSERT_EQ(gst_app_src_push_buffer(GST_APP_SRC(src.get()), buffer), GST_FLOW_OK);  // takes it
  }
  ASSERT_EQ(gst_app_src_end_of_stream(GST_APP_SRC(src.get())), GST_FLOW_OK);
  drivers::gst::BusPtr bus(gst_element_get_bus(pipeline.get()));
  const drivers::gst::MessagePtr message(
      gst_bus_timed_pop_filtered(bus.get(), 30 * GST_SECOND,
                                 static_cast<GstMessageType>(GST_MESSAGE_EOS | GST_MESSAGE_ERROR)));
  gst_element_set_state(pipeline.get(), GST_STATE_NULL);
  ASSERT_TRUE(message) << "no EOS from the writer within 30 s";
  ASSERT_EQ(GST_MESSAGE_TYPE(message.get()), GST_MESSAGE_EOS) << "the writer failed";
}

void WriteMjpegAvi(const std::string& path, const std::vector<cv::Mat>& frames, int fps,
                   int quality) {
  WriteVideo(path, frames, fps,
             "videoconvert ! jpegenc quality=" + std::to_string(quality) + " ! avimux");
}

void WriteRawMkv(const std::string& path, const std::vector<cv::Mat>& frames, int fps) {
  WriteVideo(path, frames, fps, "matroskamux");
}

LoopbackRtspServer::LoopbackRtspServer(const std::string& launch) {
  drivers::InitGStreamer();
  context_ = g_main_context_new();
  loop_ = g_main_loop_new(context_, FALSE);
  server_ = gst_rtsp_server_new();
  gst_rtsp_server_set_address(server_, "127.0.0.1");
  gst_rtsp_server_set_service(server_, "0");  // a free port; kept after the first bind
  GstRTSPMountPoints* mounts = gst_rtsp_server_get_mount_points(server_);
  GstRTSPMediaFactory* factory = gst_rtsp_media_factory_new();
  gst_rtsp_media_factory_set_launch(factory, launch.c_str());
  gst_rtsp_mount_points_add_factory(mounts, "/stereo", factory);  // takes the factory
  g_object_unref(mounts);
  thread_ = std::thread([this] {
    g_main_context_push_thread_default(context_);
    g_main_loop_run(loop_);
    g_main_context_pop_thread_default(context_);
  });
}

LoopbackRtspServer::~LoopbackRtspServer() {
  Stop();
  RunOnLoop([this] { g_main_loop_quit(loop_); });
  thread_.join();
  g_object_unref(server_);
  g_main_loop_unref(loop_);
  g_main_context_unref(context_);
}

int LoopbackRtspServer::Serve() {
  int port = -1;
  RunOnLoop([&] {
    GError* error = nullptr;
    source_ = gst_rtsp_server_create_source(server_, nullptr, &error);
    if (source_ == nullptr) {
      ADD_FAILURE() << "cannot listen: " << (error != nullptr ? error->message : "?");
      if (error != nullptr) g_error_free(error);
      return;
    }
    g_source_attach(source_, context_);
    port = gst_rtsp_server_get_bound_port(server_);
  });
  return port;
}

void LoopbackRtspServer::Stop() {
  RunOnLoop([this] {
    GList* kept = gst_rtsp_server_client_filter(
        server_, [](GstRTSPServer*, GstRTSPClient*, gpointer) { return GST_RTSP_FILTER_REMOVE; },
        nullptr);
    g_list_free_full(kept, g_object_unref);
    if (source_ != nullptr) {
      g_source_destroy(source_);
      g_source_unref(source_);
      source_ = nullptr;
    }
  });
}

// The call is shared with the callback, so that it outlives a wait that times out. GLib hands it
// over with locks ThreadSanitizer cannot see: HandOver/TakeOver tell it of that order, the
// call's mutex does the rest.
void LoopbackRtspServer::RunOnLoop(std::function<void()> work) {
  struct Call {
    std::mutex mu;
    std::condition_variable cv;
    std::function<void()> work;  // (mu)
    bool done = false;           // (mu)
  };
  auto call = std::make_shared<Call>();
  {
    std::lock_guard lock(call->mu);
    call->work = std::move(work);
  }
  auto* shared = new std::shared_ptr<Call>(call);
  HandOver(shared);
  g_main_context_invoke_full(
      context_, G_PRIORITY_DEFAULT,
      [](gpointer data) -> gboolean {
        TakeOver(data);
        Call& c = **static_cast<std::shared_ptr<Call>*>(data);
        std::lock_guard lock(c.mu);
        c.work();
        c.done = true;
        c.cv.notify_all();
        return G_SOURCE_REMOVE;
      },
      shared, [](gpointer data) { delete static_cast<std::shared_ptr<Call>*>(data); });
  std::unique_lock lock(call->mu);
  if (!call->cv.wait_for(lock, std::chrono::seconds(30), [&] { return call->done; })) {
    // The work refers to its caller's stack: it must not run after the caller returned.
    std::fprintf(stderr, "the RTSP server's thread did not run a call within 30 s\n");
    std::abort();
  }
}

}  // namespace stevi::testing
