// Start-up configuration shared by stevi-server and stevi-process: the config file (protobuf text
// format or JSON of stevi.v1.ServerConfig), command-line flags over it, and what they build.
#pragma once

#include <chrono>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "core/common/error.h"
#include "core/pipeline/config.h"
#include "drivers/stereo_source.h"
#include "drivers/aravis/aravis_source.h"
#include "drivers/recording/replay_source.h"
#include "drivers/synthetic/chessboard_source.h"
#include "drivers/synthetic/synthetic_source.h"
#include "server/mcap_recording.h"
#include "server/runtime/pose_source.h"
#include "server/runtime/source_factory.h"
#include "server/server_options.h"
#include "stevi/v1/config.pb.h"

namespace stevi::server {

// Reads a config file: JSON when it starts with '{', else protobuf text format. Errors name the
// file, the line and the problem. Files over 1 MiB are refused.
Result<v1::ServerConfig> LoadServerConfig(const std::string& path);

// Parses config text into `config` (a ServerConfig, a PipelineConfig, ...) by LoadServerConfig's
// rules: JSON when the first non-blank character is '{', else protobuf text format; unknown fields
// are errors. `name` starts every error ("config /etc/stevi.conf"). Text over 1 MiB is refused.
Status ParseConfigText(const std::string& text, const std::string& name,
                       google::protobuf::Message& config);

// Cross-field checks before anything is opened: every problem named.
std::vector<std::string> ValidateServerConfig(const v1::ServerConfig& config);

// The server's own settings of `config` over their defaults (server/server_options.h), checked.
Result<ServerOptions> ServerOptionsFrom(const v1::ServerConfig& config);

// The MCAP flight log's options (--record-mcap FILE); problems named "record_mcap.FIELD".
McapRecordingOptions McapRecordingOptionsFrom(const v1::McapRecordConfig& config,
                                              std::vector<std::string>& problems);

// The pipeline configuration: core defaults, then the config's fields, then validation.
Result<pipeline::PipelineConfig> BuildPipelineConfig(const v1::PipelineConfig& config);

// The pose source of the configuration's GeoConfig (its fields over the core defaults; errors name
// them as "geo.FIELD"). `synthetic_default` is the fixed pose used when the config gives none (the
// synthetic rig's hover at Pisa), or nullopt.
Result<std::unique_ptr<PoseSource>> MakePoseSource(
    const v1::GeoConfig& config, const std::optional<geo::VehicleState>& synthetic_default);

// The drivers' options of a source config: its fields over the drivers' defaults (the synthetic
// ones over the named scenario's, the frame rates from source.fps), mapped by name through the
// drivers' field lists. Problems of the proto itself (an unknown enum value) are appended, named
// "source.KIND.FIELD"; ranges are the options' Validate().
drivers::AravisOptions AravisOptionsFrom(const v1::SourceConfig& source,
                                         std::vector<std::string>& problems);
drivers::SyntheticOptions SyntheticOptionsFrom(const v1::SourceConfig& source,
                                               std::vector<std::string>& problems);
drivers::ChessboardSourceOptions ChessboardOptionsFrom(const v1::SourceConfig& source,
                                                       std::vector<std::string>& problems);
// The GStreamer options of the gst, uvc, rtsp and video kinds (their pipelines not built yet);
// `loop_files` is the default of loop for a file.
drivers::GstOptions GstOptionsFrom(const v1::SourceConfig& source, bool loop_files,
                                   std::vector<std::string>& problems);
drivers::ReplayOptions ReplayOptionsFrom(const v1::SourceConfig& source,
                                         std::vector<std::string>& problems);

// The source kind's name ("aravis" for SOURCE_KIND_ARAVIS; the default kind for UNSPECIFIED).
std::string SourceKindName(v1::SourceKind kind);
// What the runtime's source factory takes: the kind, and every driver's options from the config's
// fields. Problems of the proto itself are appended.
SourceSpec SourceSpecFrom(const v1::SourceConfig& source, bool loop_images,
                          std::vector<std::string>& problems);

// Opens the configured source (through the runtime's source factory). `loop_images` is what an
// image source does at its end when the config does not say (the server loops; stevi-process does
// not).
Result<std::unique_ptr<drivers::StereoSource>> OpenSource(const v1::SourceConfig& config,
                                                          bool loop_images);

}  // namespace stevi::server
