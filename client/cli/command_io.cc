#include "client/cli/command_io.h"

#include <google/protobuf/util/json_util.h>

#include <algorithm>
#include <cctype>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>

#include "core/common/flags.h"

namespace stevi::client::commands {

int Usage(const std::string& problem) {
  std::cerr << "stevi: " << problem << " (see stevi --help)\n";
  return 2;
}

int RpcFailed(const Client& client, const std::string& what, const grpc::Status& status) {
  std::string message = status.error_message();
  std::replace(message.begin(), message.end(), '\n', ' ');
  if (status.error_code() == grpc::StatusCode::UNAVAILABLE ||
      status.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED) {
    std::cerr << "stevi: " << what << ": cannot reach the server at " << client.options().address
              << " (" << StatusCodeName(status.error_code()) << ": " << message << ")\n";
  } else {
    std::cerr << "stevi: " << what << ": " << StatusCodeName(status.error_code()) << ": " << message
              << "\n";
  }
  return 1;
}

StreamOptions LiveStreamOptions(const std::string& what, int attempts_before_first_frame) {
  StreamOptions options;
  options.reconnect = true;
  options.persist_once_streaming = true;
  options.max_reconnect_attempts = attempts_before_first_frame;
  options.on_event = [what](const StreamEvent& event) {
    if (event.kind == StreamEvent::Kind::kLost) {
      std::string message = event.status.error_message();
      std::replace(message.begin(), message.end(), '\n', ' ');
      std::cerr << "stevi: " << what << ": stream lost ("
                << StatusCodeName(event.status.error_code()) << ": " << message
                << "), reconnecting\n";
    } else {
      std::cerr << "stevi: " << what << ": stream back after " << std::fixed << std::setprecision(1)
                << static_cast<double>(event.gap.count()) / 1000.0 << " s\n";
    }
    std::cerr << std::flush;
  };
  return options;
}

std::string Json(const google::protobuf::Message& message) {
  google::protobuf::util::JsonPrintOptions options;
  options.preserve_proto_field_names = true;
  options.always_print_primitive_fields = true;
  std::string out;
  (void)google::protobuf::util::MessageToJsonString(message, &out, options);
  return out;
}

std::string ShortEnum(const std::string& name, const std::string& prefix) {
  std::string out = name.rfind(prefix, 0) == 0 ? name.substr(prefix.size()) : name;
  std::transform(out.begin(), out.end(), out.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  return out;
}

bool ReadFile(const std::string& path, std::string& bytes) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  std::ostringstream out;
  out << in.rdbuf();
  bytes = out.str();
  return static_cast<bool>(in) || in.eof();
}

bool WriteFile(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  return static_cast<bool>(out);
}

std::string ParseJsonFlag(const std::string& what, const Args& args, std::size_t first,
                          bool& json) {
  return flags::FlagSet(what).Switch("--json", &json).Parse(args, first);
}

std::string RecordingLine(const v1::RecordingStatus& r) {
  std::ostringstream out;
  out << (r.active() ? "RECORDING " : "stopped ") << r.dir() << ": " << r.frames_written()
      << " frames, " << std::fixed << std::setprecision(1) << r.bytes_written() / 1048576.0
      << " MiB of " << r.max_bytes() / 1048576.0 << " MiB, " << r.frames_dropped() << " dropped";
  if (!r.stop_reason().empty()) out << " (" << r.stop_reason() << ")";
  return out.str();
}

void PrintReport(const v1::CalibrationReport& report, bool json) {
  if (json) {
    std::cout << Json(report) << "\n";
    return;
  }
  std::cout << report.text();
  if (!report.text().empty() && report.text().back() != '\n') std::cout << "\n";
  std::cout << "calibration "
            << (report.calibration_id().empty() ? "(not stored)" : report.calibration_id()) << ": "
            << (report.passed() ? "passed" : "FAILED") << " its gates"
            << (report.applied() ? "; now active" : "; not applied") << "\n";
}

}  // namespace stevi::client::commands
