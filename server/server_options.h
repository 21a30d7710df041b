// The server's own settings, declared once: each field's name (its stevi.v1.ServerConfig field),
// unit, bounds, default, meaning and command-line flag. From this list come the config's checks,
// the flags of stevi-server and stevi-process (server/server_flags.h), their usage text and the
// README's table of flags; the drivers' and the pipeline's settings have lists of their own.
//
// Adding a server setting: a field here and its field in proto/stevi/v1/config.proto. The flag,
// its parsing, its bounds, its usage line and its README row follow (server/server_flags_test
// fails until the README row is regenerated: STEVI_UPDATE_README=1).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/common/fields.h"
#include "server/runtime/source_factory.h"

namespace stevi::server {

// The source kinds' names (the runtime's source factory opens them; its table must agree, which
// server/server_flags_test checks).
enum class SourceKindName { kSynthetic, kImages, kAravis, kReplay, kUvc, kRtsp, kVideo, kGst };

// The recording a replay source plays.
struct ReplayInput {
  std::string dir;

  std::vector<std::string> Validate() const { return fields::Check(*this); }

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    v.Text(s.dir, fields::Field("dir", "",
                                "replay: the recording to play (--record or "
                                "StartRecording made it)")
                      .Flag("replay", "DIR"));
  }
};

// The synthetic source's scene, by name (its options are drivers::SyntheticOptions').
struct SceneInput {
  std::string scene;

  std::vector<std::string> Validate() const { return fields::Check(*this); }

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    v.Text(s.scene, fields::Field("scene", "",
                                  "synthetic: airfield (default) or chessboard (a moving "
                                  "calibration board for `stevi calibrate --capture`)")
                        .Flag("scene", "NAME"));
  }
};

// stevi.v1.SourceConfig's own fields (each kind's options are the drivers' lists).
struct SourceOptions {
  static constexpr fields::ChoiceName<SourceKindName> kKindNames[] = {
      {SourceKindName::kSynthetic, "synthetic"},
      {SourceKindName::kImages, "images"},
      {SourceKindName::kAravis, "aravis"},
      {SourceKindName::kReplay, "replay"},
      {SourceKindName::kUvc, "uvc"},
      {SourceKindName::kRtsp, "rtsp"},
      {SourceKindName::kVideo, "video"},
      {SourceKindName::kGst, "gst"}};

  SourceKindName kind = SourceKindName::kSynthetic;
  std::string left;
  std::string right;
  std::string calibration;
  double fps = 10;
  SceneInput synthetic;
  ReplayInput replay;
  GstInputs gst;

  std::vector<std::string> Validate() const { return fields::Check(*this); }

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Choice(s.kind, Field("kind", "", "where the frames come from").Flag("source", "KIND"),
             kKindNames);
    v.Text(s.left, Field("left", "",
                         "images: the left images (a printf pattern or a video file); aravis: "
                         "the left camera (device id, serial or address); two-view video: a file")
                       .Flag("left", "LEFT"));
    v.Text(s.right,
           Field("right", "", "the right images or camera, as --left").Flag("right", "RIGHT"));
    v.Text(s.calibration, Field("calibration", "",
                                "calibration YAML (OpenCV FileStorage) of an images, camera or "
                                "video source; cameras without it use the data directory's "
                                "active calibration")
                              .Flag("calibration", "FILE"));
    v.Number(s.fps, Field("fps", "Hz",
                          "frames per second the source runs at (aravis: the cameras' rate; "
                          "video, gst: the rate expected)")
                        .Above(0)
                        .AtMost(1000)
                        .Flag());
    v.Nested(s.synthetic, Field("synthetic"));
    v.Nested(s.replay, Field("replay"));
    v.Nested(s.gst, Field("gst"));
  }
};

struct TlsOptions {
  std::string cert_file;
  std::string key_file;
  std::string client_ca_file;

  std::vector<std::string> Validate() const { return fields::Check(*this); }

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Text(
        s.cert_file,
        Field("cert_file", "", "PEM certificate (chain): serve TLS only").Flag("tls-cert", "FILE"));
    v.Text(s.key_file,
           Field("key_file", "", "PEM private key of the certificate").Flag("tls-key", "FILE"));
    v.Text(s.client_ca_file, Field("client_ca_file", "",
                                   "PEM CA: mutual TLS, every client needs a certificate it signed")
                                 .Flag("tls-client-ca", "FILE"));
  }
};

struct AuthOptions {
  std::string token_file;

  std::vector<std::string> Validate() const { return fields::Check(*this); }

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    v.Text(s.token_file,
           fields::Field("token_file", "",
                         "bearer token (its first line, >= 16 characters) that control calls "
                         "must carry; needs TLS unless --allow-insecure")
               .Flag("token-file", "FILE"));
  }
};

struct RecordOptions {
  std::string dir;

  std::vector<std::string> Validate() const { return fields::Check(*this); }

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    v.Text(s.dir, fields::Field("dir", "",
                                "record the raw pairs, timestamps, vehicle states and calibration "
                                "id from the start into this folder (lossless)")
                      .Flag("record", "DIR"));
  }
};

struct McapFileOptions {
  std::string file;

  std::vector<std::string> Validate() const { return fields::Check(*this); }

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    v.Text(s.file, fields::Field("file", "",
                                 "write the flight as an MCAP file for Foxglove, from start to "
                                 "shutdown (the file must not exist)")
                       .Flag("record-mcap", "FILE"));
  }
};

struct ServerOptions {
  std::string listen = "127.0.0.1:50051";
  std::string data_dir = "stevi-data";
  bool allow_insecure = false;
  int subscriber_queue_frames = 8;
  int64_t max_message_bytes = 16 << 20;
  int max_streams = 64;
  double keepalive_time_s = 30;
  double keepalive_timeout_s = 10;
  double min_client_ping_interval_s = 10;
  std::optional<int> pipeline_workers;  // unset: one per core, at most 4
  std::optional<int> opencv_threads;    // unset: 1 with several workers, else one per core
  double shutdown_grace_s = 2;
  SourceOptions source;
  TlsOptions tls;
  AuthOptions auth;
  RecordOptions record;
  McapFileOptions record_mcap;

  // Every problem, each naming its field: the bounds, the listen address's form, and who may
  // reach the server (no authentication: loopback only unless allow_insecure).
  std::vector<std::string> Validate() const;

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Text(s.listen, Field("listen", "", "address to listen on").Flag("listen", "HOST:PORT"));
    v.Text(s.data_dir, Field("data_dir", "",
                             "where calibrations are stored; its active calibration is applied "
                             "at start when it fits the source")
                           .Flag("data-dir", "DIR"));
    v.Flag(s.allow_insecure, Field("allow_insecure", "",
                                   "listen on a non-loopback address without authentication (or "
                                   "send a token without TLS): anyone who can connect may change "
                                   "the pipeline")
                                 .Flag());
    v.Number(s.subscriber_queue_frames,
             Field("subscriber_queue_frames", "frames",
                   "queued per StreamTracks subscriber before the oldest is dropped")
                 .In(1, 1024)
                 .Flag());
    v.Number(s.max_message_bytes,
             Field("max_message_bytes", "bytes", "largest message sent or received")
                 .In(64 << 10, 1 << 30)
                 .Flag());
    v.Number(s.max_streams,
             Field("max_streams", "", "StreamTracks subscribers at once").In(1, 4096).Flag());
    v.Number(s.keepalive_time_s,
             Field("keepalive_time_s", "s", "an idle connection is pinged this often")
                 .In(1, 86400)
                 .Flag());
    v.Number(s.keepalive_timeout_s,
             Field("keepalive_timeout_s", "s", "a ping unanswered this long closes the connection")
                 .In(1, 600)
                 .Flag());
    v.Number(s.min_client_ping_interval_s,
             Field("min_client_ping_interval_s", "s", "clients may ping at most this often")
                 .In(1, 86400)
                 .Flag());
    v.Number(s.pipeline_workers,
             Field("pipeline_workers", "",
                   "frames processed at once, a worker thread each; unset: one per core, at "
                   "most 4")
                 .In(1, 16)
                 .Flag());
    v.Number(s.opencv_threads,
             Field("opencv_threads", "",
                   "threads one OpenCV call may use; unset: 1 with several workers, else one "
                   "per core")
                 .In(1, 64)
                 .Flag());
    v.Number(s.shutdown_grace_s,
             Field("shutdown_grace_s", "s",
                   "a stop waits this long for calls in progress before cancelling them")
                 .In(0, 4)
                 .Flag());
    v.Nested(s.source, Field("source"));
    v.Nested(s.tls, Field("tls"));
    v.Nested(s.auth, Field("auth"));
    v.Nested(s.record, Field("record"));
    v.Nested(s.record_mcap, Field("record_mcap"));
  }
};

}  // namespace stevi::server
