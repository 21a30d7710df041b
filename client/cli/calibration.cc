// stevi calibration list [--json] | get ID [--yaml] | activate ID: the stored calibrations.
#include <iomanip>
#include <iostream>
#include <sstream>
#include <string>

#include "client/cli/commands.h"

namespace stevi::client::commands {
namespace {

void PrintCalibrationList(const v1::ListCalibrationsResponse& list) {
  std::cout << "  id            size        rms px  baseline m  gates\n";
  for (const v1::CalibrationSummary& c : list.calibrations()) {
    std::ostringstream size;
    size << c.width() << "x" << c.height();
    std::cout << (c.active() ? "* " : "  ") << std::left << std::setw(14) << c.calibration_id()
              << std::setw(12) << size.str() << std::right << std::fixed << std::setprecision(3)
              << std::setw(6) << c.rms_px() << std::setprecision(4) << std::setw(12)
              << c.baseline_m() << "  " << (c.passed() ? "passed" : "FAILED") << "\n";
  }
  if (list.calibrations_size() == 0) std::cout << "  (none stored)\n";
  std::cout << "active: " << (list.active_id().empty() ? "(the source's own)" : list.active_id())
            << "\n";
  for (const std::string& problem : list.store_problems())
    std::cout << "problem: " << problem << "\n";
}

// get ID [--yaml] or activate ID (args.size() >= 2).
int GetOrActivate(Client& client, const Args& args) {
  v1::CalibrationRecord record;
  const bool activate = args[0] == "activate";
  if (activate && args.size() != 2) return Usage("calibration activate: expected one ID");
  const bool yaml = !activate && args.size() == 3 && args[2] == "--yaml";
  if (!activate && args.size() > 2 && !yaml) {
    return Usage("calibration get: unexpected argument '" + args[2] + "'");
  }
  const grpc::Status status = activate ? client.ActivateCalibration(args[1], &record)
                                       : client.GetCalibration(args[1], &record);
  if (!status.ok()) return RpcFailed(client, "calibration " + args[0], status);
  if (yaml) {
    std::cout << record.yaml();
  } else if (activate) {
    std::cout << "active: " << record.summary().calibration_id() << "\n";
  } else {
    PrintReport(record.report(), false);
  }
  return 0;
}

}  // namespace

int Calibration(Client& client, const Args& args) {
  if (args.empty()) return Usage("calibration: expected list, get ID or activate ID");
  if (args[0] == "list") {
    return ShowResponse(client, "calibration list", args, 1, &Client::ListCalibrations,
                        PrintCalibrationList);
  }
  if ((args[0] == "get" || args[0] == "activate") && args.size() >= 2)
    return GetOrActivate(client, args);
  return Usage("calibration: expected list, get ID or activate ID");
}

const CommandSpec kCalibrationCommand = {"calibration", "stored calibrations: list, show, activate",
                                         R"(usage: stevi calibration list [--json]
       stevi calibration get ID [--yaml]
       stevi calibration activate ID

list: stored calibrations and the active one.
get: one calibration: its report, or its YAML file.
activate: switch the running server to it (between two frames).
)",
                                         &Calibration};

}  // namespace stevi::client::commands
