// AtomicWriteFile (core/common/atomic_file.h) on a real temporary folder: the exact bytes, a whole
// replacement on a rewrite, no temporary file left behind, readers that never see a torn file,
// and failures (missing folder, a file where the folder should be, a folder at the path, a failed
// write, an unwritable folder) that name the path and the step and leave the old file as it was.
#include "core/common/atomic_file.h"

#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/testing/data.h"
#include "tests/testing/status_matchers.h"

using stevi::testing::IsError;

namespace stevi {
namespace {

namespace fs = std::filesystem;
using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::StartsWith;

// The whole file as bytes.
std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  EXPECT_TRUE(in.good()) << "cannot read " << path;
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// Writes `text` with plain iostreams (the state before AtomicWriteFile is called).
void WritePlain(const std::string& path, const std::string& text) {
  std::ofstream(path, std::ios::binary) << text;
}

// Every byte value, NULs and line ends included, then a tail long enough for several writes.
std::string BinaryText() {
  std::string text;
  for (int i = 0; i < 256; ++i) text.push_back(static_cast<char>(i));
  text += std::string("\r\n\n\0end", 7);
  for (int i = 0; i < 300000; ++i) text.push_back(static_cast<char>('a' + i % 26));
  return text;
}

// One fresh folder per test (temp_directory_path plus a unique name), removed at the end.
class AtomicWriteFileTest : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = testing::MakeTempDir("stevi_atomic_file"); }
  void TearDown() override {
    std::error_code ec;
    fs::permissions(dir_, fs::perms::owner_all, fs::perm_options::add, ec);
    fs::remove_all(dir_, ec);
    EXPECT_FALSE(ec) << "cannot remove " << dir_ << ": " << ec.message();
  }

  std::string Path(const std::string& name) const { return dir_ + "/" + name; }

  // The names in the folder, sorted.
  std::vector<std::string> Names() const {
    std::vector<std::string> names;
    for (const fs::directory_entry& entry : fs::directory_iterator(dir_)) {
      names.push_back(entry.path().filename().string());
    }
    std::sort(names.begin(), names.end());
    return names;
  }

  std::string dir_;
};

TEST_F(AtomicWriteFileTest, CreatesTheFileWithTheExactBytes) {
  const std::string path = Path("data.bin");
  const std::string text = BinaryText();
  const Status s = AtomicWriteFile(path, text);
  ASSERT_TRUE(s.ok()) << s.error().message;
  EXPECT_EQ(fs::file_size(path), text.size());
  EXPECT_TRUE(ReadAll(path) == text) << "the bytes read back differ from the bytes written";
  EXPECT_EQ(Names(), std::vector<std::string>{"data.bin"});
}

TEST_F(AtomicWriteFileTest, EmptyTextGivesAnEmptyFile) {
  const std::string path = Path("empty.txt");
  ASSERT_TRUE(AtomicWriteFile(path, "").ok());
  ASSERT_TRUE(fs::is_regular_file(path));
  EXPECT_EQ(fs::file_size(path), 0u);

  // Emptying an existing file.
  WritePlain(path, "old contents");
  ASSERT_TRUE(AtomicWriteFile(path, "").ok());
  EXPECT_EQ(fs::file_size(path), 0u);
}

TEST_F(AtomicWriteFileTest, ARewriteReplacesTheWholeFile) {
  const std::string path = Path("config.yaml");
  ASSERT_TRUE(AtomicWriteFile(path, std::string(10000, 'x') + "tail").ok());
  // Shorter: nothing of the old contents is left past the new end.
  ASSERT_TRUE(AtomicWriteFile(path, "short\n").ok());
  EXPECT_EQ(ReadAll(path), "short\n");
  // Longer again, and over a file written by someone else.
  WritePlain(path, "written by hand");
  ASSERT_TRUE(AtomicWriteFile(path, "a much longer replacement text\n").ok());
  EXPECT_EQ(ReadAll(path), "a much longer replacement text\n");
  EXPECT_EQ(Names(), std::vector<std::string>{"config.yaml"});
}

TEST_F(AtomicWriteFileTest, ReplacesTheFileRatherThanWritingIntoIt) {
  // A reader holding the old file open keeps reading the old contents: the new file is a new
  // inode renamed over the path, not the old one truncated and rewritten.
  const std::string path = Path("state.txt");
  ASSERT_TRUE(AtomicWriteFile(path, "old contents\n").ok());
  std::ifstream held(path, std::ios::binary);
  ASSERT_TRUE(held.good());
  ASSERT_TRUE(AtomicWriteFile(path, "new\n").ok());
  const std::string seen_by_holder(std::istreambuf_iterator<char>(held), {});
  EXPECT_EQ(seen_by_holder, "old contents\n");
  EXPECT_EQ(ReadAll(path), "new\n");
}

TEST_F(AtomicWriteFileTest, NoTemporaryFileIsLeftBehind) {
  for (int i = 0; i < 20; ++i) {
    ASSERT_TRUE(AtomicWriteFile(Path("a.txt"), "a" + std::to_string(i)).ok());
    ASSERT_TRUE(AtomicWriteFile(Path("b.txt"), std::string(1000 * i, 'b')).ok());
  }
  EXPECT_EQ(Names(), (std::vector<std::string>{"a.txt", "b.txt"}));
  EXPECT_EQ(ReadAll(Path("a.txt")), "a19");
  EXPECT_EQ(ReadAll(Path("b.txt")), std::string(19000, 'b'));
}

TEST_F(AtomicWriteFileTest, TheFileIsReadableByOthers) {
  // mkstemp makes its file 0600; the written file is 0644 whatever the umask.
  const mode_t old_umask = ::umask(077);
  const Status s = AtomicWriteFile(Path("shared.txt"), "x");
  ::umask(old_umask);
  ASSERT_TRUE(s.ok()) << s.error().message;
  struct stat st {};
  ASSERT_EQ(::stat(Path("shared.txt").c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 07777, 0644u);
}

TEST_F(AtomicWriteFileTest, APathWithoutAFolderIsRelativeToTheWorkingDirectory) {
  const fs::path cwd = fs::current_path();
  fs::current_path(dir_);
  const Status s = AtomicWriteFile("relative.txt", "here\n");
  fs::current_path(cwd);
  ASSERT_TRUE(s.ok()) << s.error().message;
  EXPECT_EQ(ReadAll(Path("relative.txt")), "here\n");
  EXPECT_EQ(Names(), std::vector<std::string>{"relative.txt"});
}

TEST_F(AtomicWriteFileTest, AMissingFolderFailsNamingThePathAndTheStep) {
  const std::string path = Path("no_such_folder/file.txt");
  const Status s = AtomicWriteFile(path, "text");
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(s, IsError(ErrorCode::kInternal));
  EXPECT_THAT(s.error().message,
              AllOf(StartsWith(path + ": "), HasSubstr("cannot create a temporary file beside it"),
                    HasSubstr(std::strerror(ENOENT))));
  EXPECT_FALSE(fs::exists(Path("no_such_folder")));
  EXPECT_TRUE(Names().empty());
}

TEST_F(AtomicWriteFileTest, AFileWhereTheFolderShouldBeFailsAndIsLeftAlone) {
  const std::string blocker = Path("not_a_folder");
  WritePlain(blocker, "keep me");
  const std::string path = blocker + "/file.txt";
  const Status s = AtomicWriteFile(path, "text");
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(s, IsError(ErrorCode::kInternal));
  EXPECT_THAT(s.error().message,
              AllOf(StartsWith(path + ": "), HasSubstr("cannot create a temporary file beside it"),
                    HasSubstr(std::strerror(ENOTDIR))));
  EXPECT_EQ(ReadAll(blocker), "keep me");
  EXPECT_EQ(Names(), std::vector<std::string>{"not_a_folder"});
}

TEST_F(AtomicWriteFileTest, AFolderAtThePathFailsAtTheRenameAndCleansUp) {
  // The temporary file is written, but cannot replace a folder: it is removed again and the
  // folder and its contents stay.
  const std::string path = Path("a_folder");
  fs::create_directory(path);
  WritePlain(path + "/inside.txt", "inside");
  const Status s = AtomicWriteFile(path, "text");
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(s, IsError(ErrorCode::kInternal));
  EXPECT_THAT(s.error().message, AllOf(StartsWith(path + ": "), HasSubstr("rename failed"),
                                       HasSubstr(std::strerror(EISDIR))));
  EXPECT_TRUE(fs::is_directory(path));
  EXPECT_EQ(ReadAll(path + "/inside.txt"), "inside");
  EXPECT_EQ(Names(), std::vector<std::string>{"a_folder"});
}

TEST_F(AtomicWriteFileTest, AFailedWriteLeavesTheOldFileAndNoTemporary) {
  // RLIMIT_FSIZE makes write() fail with EFBIG past 4 KiB (root included), as a full disk would.
  const std::string path = Path("calibration.yaml");
  WritePlain(path, "the old, good contents\n");
  struct rlimit saved {};
  ASSERT_EQ(::getrlimit(RLIMIT_FSIZE, &saved), 0);
  struct rlimit small = saved;
  small.rlim_cur = 4096;
  const sighandler_t saved_handler = ::signal(SIGXFSZ, SIG_IGN);
  ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &small), 0) << std::strerror(errno);
  const Status s = AtomicWriteFile(path, std::string(100000, 'n'));
  ::setrlimit(RLIMIT_FSIZE, &saved);
  ::signal(SIGXFSZ, saved_handler);

  ASSERT_FALSE(s.ok());
  EXPECT_THAT(s, IsError(ErrorCode::kInternal));
  EXPECT_THAT(s.error().message, AllOf(StartsWith(path + ": "), HasSubstr("write failed"),
                                       HasSubstr(std::strerror(EFBIG))));
  EXPECT_EQ(ReadAll(path), "the old, good contents\n");
  EXPECT_EQ(Names(), std::vector<std::string>{"calibration.yaml"});
}

TEST_F(AtomicWriteFileTest, AnUnwritableFolderFailsAndLeavesTheOldFile) {
  const std::string path = Path("locked.txt");
  WritePlain(path, "unchanged");
  fs::permissions(dir_, fs::perms::owner_read | fs::perms::owner_exec);
  // Root (CAP_DAC_OVERRIDE) writes anyway: then this case cannot be made.
  const bool writable = ::access(dir_.c_str(), W_OK) == 0;
  if (writable) {
    fs::permissions(dir_, fs::perms::owner_all);
    GTEST_SKIP() << "a folder without write permission is still writable for this user (root?)";
  }
  const Status s = AtomicWriteFile(path, "replaced");
  fs::permissions(dir_, fs::perms::owner_all);
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(s, IsError(ErrorCode::kInternal));
  EXPECT_THAT(s.error().message,
              AllOf(StartsWith(path + ": "), HasSubstr("cannot create a temporary file beside it"),
                    HasSubstr(std::strerror(EACCES))));
  EXPECT_EQ(ReadAll(path), "unchanged");
  EXPECT_EQ(Names(), std::vector<std::string>{"locked.txt"});
}

TEST_F(AtomicWriteFileTest, ReadersSeeTheOldOrTheNewFileNeverATornOne) {
  // Two large contents of different lengths, rewritten in turn while another thread reads: every
  // read is one of them whole (a truncate-and-write would show an empty or a mixed file).
  const std::string path = Path("live.txt");
  const std::string a(300000, 'a');
  const std::string b = std::string(200000, 'b') + "end";
  ASSERT_TRUE(AtomicWriteFile(path, a).ok());
  std::atomic<bool> done{false};
  int reads = 0, torn = 0;
  std::thread reader([&] {
    while (!done.load()) {
      const std::string seen = ReadAll(path);
      ++reads;
      if (seen != a && seen != b) ++torn;
    }
  });
  int failed_writes = 0;
  for (int i = 0; i < 100; ++i) {
    if (!AtomicWriteFile(path, i % 2 == 0 ? b : a).ok()) ++failed_writes;
  }
  done = true;
  reader.join();
  EXPECT_EQ(failed_writes, 0);
  EXPECT_EQ(torn, 0) << "of " << reads << " reads";
  EXPECT_GT(reads, 0);
  EXPECT_EQ(ReadAll(path), a);
  EXPECT_EQ(Names(), std::vector<std::string>{"live.txt"});
}

}  // namespace
}  // namespace stevi
