# GStreamer pipelines as a stereo source (drivers/gstreamer): the pipeline builders and escaping,
# then the source against real pipelines: an MJPEG AVI written by the test, a gst-rtsp-server on
# loopback, two videotestsrc, and the errors at the start. Included from tests/CMakeLists.txt;
# paths are relative to tests/.
if(TARGET stevi_gstreamer)
  pkg_check_modules(GStreamerRtspServer REQUIRED IMPORTED_TARGET GLOBAL gstreamer-rtsp-server-1.0)
  # The GStreamer peers the tests meet: an AVI written by a real pipeline, a real RTSP server.
  add_library(stevi_testing_gst STATIC testing/gst_testing.cc)
  target_include_directories(stevi_testing_gst PUBLIC ${PROJECT_SOURCE_DIR})
  target_link_libraries(stevi_testing_gst PUBLIC stevi_gstreamer PkgConfig::GStreamerRtspServer
    opencv_core GTest::gtest PRIVATE PkgConfig::GStreamer PkgConfig::GStreamerApp Threads::Threads
    stevi_warnings)

  stevi_test(drivers/gstreamer/pipelines_test SOURCES drivers/gstreamer/pipelines_test.cc
    drivers/gstreamer/lsan_glib_quarks.cc
    LIBS stevi_gstreamer PkgConfig::GStreamer LABELS gstreamer TIMEOUT 60)
  stevi_test(drivers/gstreamer/video_file_test SOURCES drivers/gstreamer/video_file_test.cc
    drivers/gstreamer/lsan_glib_quarks.cc
    LIBS stevi_gstreamer stevi_drivers stevi_testing_gst PkgConfig::GStreamer
         opencv_imgproc opencv_imgcodecs LABELS gstreamer TIMEOUT 300)
  stevi_test(drivers/gstreamer/rtsp_test SOURCES drivers/gstreamer/rtsp_test.cc
    drivers/gstreamer/lsan_glib_quarks.cc
    LIBS stevi_gstreamer stevi_testing_gst PkgConfig::GStreamer Threads::Threads
    LABELS gstreamer TIMEOUT 300)
  stevi_test(drivers/gstreamer/gst_source_test SOURCES drivers/gstreamer/gst_source_test.cc
    drivers/gstreamer/lsan_glib_quarks.cc
    LIBS stevi_gstreamer PkgConfig::GStreamer LABELS gstreamer TIMEOUT 300)
endif()
