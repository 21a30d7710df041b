// stevi status [--json]: source state, frame rates, drops, stage timings, camera pairing,
// recording and subscribers.
#include <iomanip>
#include <iostream>
#include <string>

#include "client/cli/commands.h"

namespace stevi::client::commands {
namespace {

void PrintImages(const v1::GetStatusResponse& s) {
  if (s.image_width() <= 0) return;
  std::cout << "images       " << s.image_width() << "x" << s.image_height();
  if (s.binning() > 1) {
    std::cout << ", processed at " << s.processed_width() << "x" << s.processed_height()
              << " (binned " << s.binning() << "x" << s.binning()
              << ": pipeline.max_width_px; boxes are in these pixels)";
  }
  std::cout << "\n";
}

void PrintPairing(const v1::PairingStatus& p) {
  if (p.pairs() > 0 || p.unpaired_dropped() > 0 || p.incomplete_dropped() > 0 ||
      p.reconnects() > 0) {
    std::cout << "\npairing      " << p.pairs() << " pairs, " << p.unpaired_dropped()
              << " unpaired dropped, " << p.incomplete_dropped() << " incomplete dropped, "
              << p.reconnects() << " reconnects; skew last " << p.last_skew_ns() * 1e-6
              << " ms, mean |skew| " << p.mean_abs_skew_ns() * 1e-6 << " ms, max "
              << p.max_abs_skew_ns() * 1e-6 << " ms";
  }
}

void PrintStatusText(const v1::GetStatusResponse& s) {
  std::cout << std::fixed << std::setprecision(1);
  std::cout << "source       " << s.source() << " ("
            << ShortEnum(v1::SourceState_Name(s.source_state()), "SOURCE_STATE_") << ")\n";
  if (!s.source_error().empty()) std::cout << "last error   " << s.source_error() << "\n";
  std::cout << "algorithm    " << ShortEnum(v1::Algorithm_Name(s.algorithm()), "ALGORITHM_") << "\n"
            << "calibration  " << s.calibration_id() << "\n"
            << "uptime       " << s.uptime_s() << " s\n"
            << "frames       " << s.frames_captured() << " captured, " << s.frames_processed()
            << " processed, " << s.frames_dropped_capture() << " dropped at capture, "
            << s.frames_failed() << " failed\n"
            << "rate         " << s.fps_in() << " fps in, " << s.fps_out() << " fps out\n"
            << "workers      " << s.pipeline_workers() << " (frames at once), OpenCV threads "
            << s.opencv_threads() << "\n";
  PrintImages(s);
  std::cout << std::setprecision(2) << "timings      ";
  for (int i = 0; i < s.timings_size(); ++i) {
    std::cout << (i ? ", " : "") << s.timings(i).stage() << " " << s.timings(i).ms() << " ms";
  }
  PrintPairing(s.pairing());
  if (!s.recording().dir().empty()) {
    std::cout << "\nrecording    " << RecordingLine(s.recording());
  }
  std::cout << "\nsubscribers  " << s.subscribers_size() << "\n";
  for (const v1::SubscriberStatus& sub : s.subscribers()) {
    std::cout << "  #" << sub.subscriber_id() << " " << sub.peer() << ": " << sub.frames_sent()
              << " sent, " << sub.frames_dropped() << " dropped\n";
  }
}

}  // namespace

int Status(Client& client, const Args& args) {
  return ShowResponse(client, "status", args, 0, &Client::GetStatus, PrintStatusText);
}

const CommandSpec kStatusCommand = {
    "status", "the server's source, rates, drops, timings, pairing and recording",
    R"(usage: stevi status [--json]

Source state, frame rates, drops, stage timings, camera pairing (skew, unpaired and incomplete
frames, reconnects), recording, subscribers.
)",
    &Status};

}  // namespace stevi::client::commands
