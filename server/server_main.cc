// stevi-server: serves obstacle tracks from a stereo rig over gRPC.
#include <signal.h>

#include <cstdio>
#include <iostream>
#include <set>
#include <string>

#include "core/common/allocator.h"
#include "server/app_config.h"
#include "server/runtime/log.h"
#include "server/server.h"

namespace {

constexpr char kUsage[] = R"(usage: stevi-server [flags]

Serves obstacle tracks from a stereo rig over gRPC (services stevi.v1.ObstacleService and
stevi.v1.CalibrationService).
With no flags: the built-in synthetic rig, the canonical algorithm, listening on 127.0.0.1:50051.

  --listen HOST:PORT     address to listen on (default 127.0.0.1:50051)
  --config FILE          stevi.v1.ServerConfig in protobuf text format or JSON; flags override it
  --source KIND          synthetic (default), images, aravis (two GenICam cameras), replay,
                         uvc (a UVC stereo camera or two webcams), rtsp (an RTSP camera), video
                         (a video file) or gst (any GStreamer pipeline)
  --left PATTERN|VIDEO   images: left images as a printf pattern ("left_%04d.png") or a video file
         ID              aravis: the left camera's device id, serial number or IP address
  --right PATTERN|VIDEO  images: right images, likewise; aravis: the right camera
  --calibration FILE     images, aravis: calibration YAML (OpenCV FileStorage); aravis without
                         it uses the data directory's active calibration (or runs uncalibrated:
                         frames flow for `stevi calibrate --capture`, but no tracks)
  --fps N                frames per second to run the source at (default 10; aravis: the
                         cameras' frame rate, default 30)
  --roi WxH              aravis: centred region of interest on both cameras (default 640x480)
  --exposure-us US       aravis: fixed exposure (default automatic)
  --gain-db DB           aravis: fixed gain (default automatic)
  --trigger MODE         aravis: free (default), software, or hardware:LINE (e.g. hardware:Line0)
  --timestamps CLOCK     aravis: pair by the cameras' clocks (camera, default; they must share a
                         time base, e.g. PTP) or by arrival time (host, for unsynchronised cameras)
  --layout L             uvc, rtsp, video, gst: how the views arrive: side-by-side (default),
                         top-bottom, or two (two devices, URLs or files: --left and --right;
                         gst: --left-pipeline and --right-pipeline), paired by capture time
  --device DEV           uvc: the V4L2 device (default /dev/video0)
  --size WxH             uvc: the size of one view (the camera is asked for the frame holding
                         both: a 2560x960 side-by-side camera is --size 1280x960); others: the
                         size expected (default: as the stream comes)
  --url URL              rtsp: rtsp://host[:port]/path
  --latency-ms MS        rtsp: the jitter buffer (default 100)
  --file FILE            video: a video file GStreamer decodes (MJPEG AVI or MKV with Debian's
                         base and good plugins; H.264 needs plugins-bad and libav)
  --pipeline P           gst: a gst-launch-1.0 pipeline up to the frames ("v4l2src ! jpegdec");
                         the server appends the conversion to grey and its sink
  --left-pipeline P, --right-pipeline P
                         gst with --layout two: one pipeline per camera
  --replay DIR           replay: the recording to play (made with --record or StartRecording)
  --rate R|max           replay: speed against the recorded timing (default 1; max = no pacing)
  --record DIR           record the raw pairs, timestamps, vehicle states and calibration id
                         from the start into DIR (lossless; stops at record.max_bytes, 4 GiB)
  --record-mcap FILE     write the flight as an MCAP file for Foxglove, from start to shutdown:
                         the station's channels (tracks, status, annotations, scene, vehicle)
                         and the left and disparity images (FILE must not exist)
  --mcap-image-hz N      images per second of each kind in the MCAP file (default 5; 0 = none)
  --scene NAME           synthetic: airfield (default) or chessboard (a moving calibration board,
                         9x6 inner corners of 100 mm squares, for `stevi calibrate --capture`)
  --data-dir DIR         where calibrations are stored (default ./stevi-data); its active
                         calibration is applied at start when it fits the source
  --algorithm NAME       canonical (default), stevie (stereo + edges) or stevis (stereo + saliency)
  --tls-cert FILE        PEM certificate: serve TLS only (with --tls-key)
  --tls-key FILE         PEM private key of --tls-cert
  --tls-client-ca FILE   PEM CA: mutual TLS, every client needs a certificate it signed
  --token-file FILE      bearer token (first line, >= 16 characters) that control calls must carry
  --allow-insecure       listen on a non-loopback address without authentication (or send a
                         token without TLS): anyone who can connect may change the pipeline
  --help                 this text
)";

}  // namespace

int main(int argc, char** argv) {
  stevi::KeepFrameMemory();  // first: before any thread starts
  using namespace stevi;
  const std::set<std::string> known = {
      "listen",   "config",    "source",        "left",           "right",       "calibration",
      "fps",      "algorithm", "data-dir",      "scene",          "replay",      "rate",
      "record",   "roi",       "exposure-us",   "gain-db",        "trigger",     "timestamps",
      "tls-cert", "tls-key",   "tls-client-ca", "token-file",     "record-mcap", "mcap-image-hz",
      "layout",   "pipeline",  "left-pipeline", "right-pipeline", "device",      "url",
      "file",     "size",      "latency-ms"};
  Result<server::Flags> flags = server::ParseFlags(argc, argv, known, {"help", "allow-insecure"});
  if (!flags.ok()) {
    std::cerr << "stevi-server: " << flags.error().message << "\n";
    return 2;
  }
  if (flags->values.count("help")) {
    std::cout << kUsage;
    return 0;
  }
  if (!flags->positional.empty()) {
    std::cerr << "stevi-server: unexpected argument '" << flags->positional.front() << "'\n";
    return 2;
  }

  v1::ServerConfig config;
  if (auto it = flags->values.find("config"); it != flags->values.end()) {
    Result<v1::ServerConfig> loaded = server::LoadServerConfig(it->second);
    if (!loaded.ok()) {
      std::cerr << "stevi-server: " << loaded.error().message << "\n";
      return 2;
    }
    config = std::move(loaded).value();
  }
  if (Status applied = server::ApplyFlags(*flags, config); !applied.ok()) {
    std::cerr << "stevi-server: " << applied.error().message << "\n";
    return 2;
  }

  // Block the stop signals in every thread; the main thread waits for them below.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGINT);
  sigaddset(&stop_signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);

  using server::Log;
  using server::LogLevel;
  Result<std::unique_ptr<server::Server>> server = server::Server::Start(config);
  if (!server.ok()) {
    Log(LogLevel::kError, "start_failed", {{"error", server.error().message}});
    return 1;
  }
  for (const std::string& problem : (*server)->calibration().problems()) {
    Log(LogLevel::kWarning, "calibration_store", {{"problem", problem}});
  }
  const server::EngineStatus status = (*server)->engine().Status();
  const std::string& listen = (*server)->listen_address();
  Log(LogLevel::kInfo, "serving",
      {{"source", status.source},
       {"algorithm", std::string(pipeline::AlgorithmName(status.algorithm))},
       {"listen", listen.substr(0, listen.rfind(':')) + ":" + std::to_string((*server)->port())},
       {"tls", config.tls().has_cert_file() ? "on" : "off"},
       {"auth",
        config.auth().has_token_file() || config.tls().has_client_ca_file() ? "on" : "off"}});

  int signal_number = 0;
  sigwait(&stop_signals, &signal_number);
  Log(LogLevel::kInfo, "shutting_down",
      {{"signal", signal_number == SIGINT ? "SIGINT" : "SIGTERM"}});
  (*server)->Shutdown();
  Log(LogLevel::kInfo, "stopped");
  return 0;
}
