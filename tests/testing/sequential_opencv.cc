// Linked into every test under ThreadSanitizer only (tests/CMakeLists.txt): OpenCV runs its
// parallel loops (cv::parallel_for_, ours and its own) on the calling thread. Debian's OpenCV
// hands a loop to TBB's workers and back through TBB's own synchronisation, which TSan cannot see,
// so every loop body would be reported as racing with the code after the loop. The servers'
// engine already runs OpenCV on one thread whenever it has more than one pipeline worker.
#include <opencv2/core/utility.hpp>

namespace {

const bool kSequentialOpenCv = [] {
  cv::setNumThreads(0);
  return true;
}();

}  // namespace
