// stevi snapshot --out PREFIX: the disparity maps, the left and annotated images, and the rest of
// the snapshot as JSON.
#include <iostream>
#include <string>
#include <utility>
#include <vector>

#include "client/cli/commands.h"

namespace stevi::client::commands {

int Snapshot(Client& client, const Args& args) {
  if (args.size() != 2 || args[0] != "--out" || args[1].empty()) {
    return Usage("snapshot: expected --out PREFIX");
  }
  const std::string& prefix = args[1];
  v1::DisparitySnapshot snapshot;
  if (grpc::Status status = client.GetDisparitySnapshot(&snapshot, /*annotated=*/true);
      !status.ok()) {
    return RpcFailed(client, "snapshot", status);
  }
  v1::DisparitySnapshot meta = snapshot;
  meta.clear_disparity_png16();
  meta.clear_disparity_colour_png();
  meta.clear_left_png();
  meta.clear_annotated_png();
  const std::vector<std::pair<std::string, std::string>> files = {
      {prefix + "_disparity16.png", snapshot.disparity_png16()},
      {prefix + "_disparity_colour.png", snapshot.disparity_colour_png()},
      {prefix + "_left.png", snapshot.left_png()},
      {prefix + "_annotated.png", snapshot.annotated_png()},
      {prefix + "_meta.json", Json(meta) + "\n"}};
  for (const auto& [path, bytes] : files) {
    if (!WriteFile(path, bytes)) {
      std::cerr << "stevi: snapshot: cannot write " << path << "\n";
      return 1;
    }
    std::cout << path << "\n";
  }
  return 0;
}

const CommandSpec kSnapshotCommand = {"snapshot",
                                      "the current disparity, images and annotated frame, as files",
                                      R"(usage: stevi snapshot --out PREFIX

Writes PREFIX_disparity16.png, PREFIX_disparity_colour.png, PREFIX_left.png, PREFIX_annotated.png
(boxes, ids, ranges) and PREFIX_meta.json.
)",
                                      &Snapshot};

}  // namespace stevi::client::commands
