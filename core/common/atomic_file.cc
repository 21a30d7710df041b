#include "core/common/atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>

namespace stevi {
namespace {

std::string ErrnoText() { return std::strerror(errno); }

}  // namespace

Status AtomicWriteFile(const std::string& path, const std::string& text) {
  std::string tmp_path = path + ".tmp-XXXXXX";
  const int fd = ::mkstemp(tmp_path.data());
  if (fd < 0) {
    return Internal(path + ": cannot create a temporary file beside it (" + ErrnoText() + ")");
  }
  auto fail = [&](const std::string& what) -> Status {
    const std::string reason = ErrnoText();
    ::unlink(tmp_path.c_str());
    return Internal(path + ": " + what + " (" + reason + ")");
  };
  ::fchmod(fd, 0644);
  std::size_t written = 0;
  while (written < text.size()) {
    const ssize_t n = ::write(fd, text.data() + written, text.size() - written);
    if (n < 0) {
      if (errno == EINTR) continue;
      ::close(fd);
      return fail("write failed");
    }
    written += static_cast<std::size_t>(n);
  }
  if (::fsync(fd) != 0) {
    ::close(fd);
    return fail("fsync failed");
  }
  if (::close(fd) != 0) return fail("close failed");
  if (::rename(tmp_path.c_str(), path.c_str()) != 0) return fail("rename failed");
  std::filesystem::path dir = std::filesystem::path(path).parent_path();
  if (dir.empty()) dir = std::filesystem::path(".");
  if (const int dir_fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY); dir_fd >= 0) {
    ::fsync(dir_fd);  // Best effort: the rename is durable once the directory is synced.
    ::close(dir_fd);
  }
  return Status::Ok();
}

}  // namespace stevi
