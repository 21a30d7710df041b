#include "core/calibration/store.h"

#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>

#include "tests/core/geometry/calibration_fixtures.h"
#include "tests/testing/data.h"
#include "tests/testing/status_matchers.h"

using stevi::testing::IsError;

namespace stevi::calibration {
namespace {

using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::IsEmpty;

namespace fs = std::filesystem;

// The raw rig of the geometry tests with the left focal length 520 + i px and the baseline
// 10 cm + i mm, with its rectification terms.
geometry::StereoCalibration MakeCalibration(int i) {
  geometry::StereoCalibration c = geometry::fixtures::RawCalibration();
  c.M1(0, 0) += i;
  c.T[0] -= 0.001 * i;
  cv::Mat R1, R2, P1, P2, Q;
  cv::stereoRectify(cv::Mat(c.M1), c.D1, cv::Mat(c.M2), c.D2, c.image_size, cv::Mat(c.R),
                    cv::Mat(c.T), R1, R2, P1, P2, Q, cv::CALIB_ZERO_DISPARITY, 0);
  c.R1 = cv::Matx33d(R1);
  c.R2 = cv::Matx33d(R2);
  c.P1 = cv::Matx34d(P1);
  c.P2 = cv::Matx34d(P2);
  c.Q = cv::Matx44d(Q);
  return c;
}

CalibrationReport MakeReport(bool passed, double rms_px) {
  CalibrationReport r;
  r.created_unix_ms = 1'700'000'000'123;
  r.image_size = cv::Size(640, 480);
  r.board = BoardSpec{9, 6, 0.03};
  r.detector = "sector_based_then_classic + saddle_point";
  r.pairs_given = 12;
  r.pairs_used = 1;
  r.pairs.push_back({0, "view0", 0.2, 0.25, 0.1, 0.3, 0.31});
  r.rejected.push_back({1, "view1", RejectReason::kNoBoardRight,
                        "no board of 9x6 inner corners found in the right image"});
  r.rms_px = rms_px;
  r.passed = passed;
  if (!passed) {
    r.failures.push_back({"max_rms_px", rms_px, 1.0,
                          "stereo RMS reprojection error 1.700 px > 1.000 px (max_rms_px)"});
  }
  r.coverage_grid = cv::Size(10, 8);
  return r;
}

std::string ReadText(const std::string& path) {
  std::ifstream in(path);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

void WriteText(const std::string& path, const std::string& text) { std::ofstream(path) << text; }

std::unique_ptr<CalibrationStore> OpenClean(const std::string& dir) {
  Result<OpenedStore> opened = CalibrationStore::Open(dir);
  EXPECT_TRUE(opened.ok()) << opened.error().message;
  EXPECT_THAT(opened->problems, IsEmpty());
  return std::move(opened->store);
}

TEST(CalibrationId, NamesAndParses) {
  EXPECT_EQ(CalibrationId{1}.Name(), "cal-000001");
  EXPECT_EQ(CalibrationId{1234567}.Name(), "cal-1234567");
  EXPECT_EQ(CalibrationId::Parse("cal-000042")->value, 42);
  EXPECT_EQ(CalibrationId::Parse("cal-42")->value, 42);
  for (const char* bad :
       {"", "cal-", "cal-0", "cal-12a", "42", "cal--1", "CAL-000001", "cal-0000000000000001"}) {
    EXPECT_FALSE(CalibrationId::Parse(bad).has_value()) << bad;
  }
}

TEST(CalibrationStore, RoundTripsACalibrationAndItsReport) {
  const std::string dir = testing::MakeTempDir("stevi-store") + "/calibrations";  // created by Open
  std::unique_ptr<CalibrationStore> store = OpenClean(dir);
  EXPECT_THAT(store->List(), IsEmpty());
  EXPECT_FALSE(store->ActiveId().has_value());
  EXPECT_THAT(store->Active(), IsError(ErrorCode::kFailedPrecondition));

  const geometry::StereoCalibration calibration = MakeCalibration(0);
  const Result<CalibrationId> id = store->Add(calibration, MakeReport(true, 0.21));
  ASSERT_TRUE(id.ok()) << id.error().message;
  EXPECT_EQ(id->Name(), "cal-000001");
  EXPECT_TRUE(fs::exists(dir + "/cal-000001.yaml"));
  EXPECT_TRUE(fs::exists(dir + "/cal-000001.report.yaml"));
  EXPECT_FALSE(store->ActiveId().has_value()) << "Add does not activate";

  const std::vector<CalibrationSummary> list = store->List();
  ASSERT_EQ(list.size(), 1u);
  EXPECT_EQ(list[0].id, *id);
  EXPECT_EQ(list[0].created_unix_ms, 1'700'000'000'123);
  EXPECT_EQ(list[0].rms_px, 0.21);
  EXPECT_TRUE(list[0].passed);
  EXPECT_FALSE(list[0].swap_left_right);
  EXPECT_NEAR(list[0].baseline_m, cv::norm(calibration.T), 1e-12);
  EXPECT_EQ(list[0].image_size, cv::Size(640, 480));

  const Result<StoredCalibration> stored = store->Get(*id);
  ASSERT_TRUE(stored.ok()) << stored.error().message;
  EXPECT_EQ(stored->yaml_text, ReadText(dir + "/cal-000001.yaml"));
  EXPECT_LT(cv::norm(stored->calibration.M1, calibration.M1, cv::NORM_INF), 1e-12);
  EXPECT_LT(cv::norm(stored->calibration.D2, calibration.D2, cv::NORM_INF), 1e-12);
  EXPECT_LT(cv::norm(stored->calibration.T - calibration.T), 1e-12);
  ASSERT_TRUE(stored->calibration.P2.has_value());
  EXPECT_LT(cv::norm(*stored->calibration.P2, *calibration.P2, cv::NORM_INF), 1e-9);
  EXPECT_EQ(stored->report.rms_px, 0.21);
  EXPECT_EQ(stored->report.pairs.size(), 1u);
  EXPECT_EQ(stored->report.rejected[0].reason, RejectReason::kNoBoardRight);
  EXPECT_EQ(stored->report.board.Name(), "9x6");

  // The calibration file is one OpenCV's own tools read.
  cv::FileStorage opencv(dir + "/cal-000001.yaml", cv::FileStorage::READ);
  cv::Mat m1;
  opencv["M1"] >> m1;
  EXPECT_EQ(m1.at<double>(0, 0), 520);

  // A report without a time gets one.
  CalibrationReport untimed = MakeReport(true, 0.3);
  untimed.created_unix_ms = 0;
  const Result<CalibrationId> second = store->Add(MakeCalibration(1), untimed);
  ASSERT_TRUE(second.ok());
  EXPECT_GT(store->List().back().created_unix_ms, 1'700'000'000'123);

  EXPECT_EQ(store->Get(CalibrationId{9}).error().code, ErrorCode::kNotFound);
}

TEST(CalibrationStore, IdsIncreaseAndSurviveReopening) {
  const std::string dir = testing::MakeTempDir("stevi-store");
  {
    std::unique_ptr<CalibrationStore> store = OpenClean(dir);
    for (int i = 0; i < 3; ++i)
      EXPECT_EQ(store->Add(MakeCalibration(i), MakeReport(true, 0.2))->value, i + 1);
  }
  {
    std::unique_ptr<CalibrationStore> store = OpenClean(dir);
    ASSERT_EQ(store->List().size(), 3u);
    EXPECT_EQ(store->List()[2].id.value, 3);
    EXPECT_NEAR(store->List()[2].baseline_m, cv::norm(MakeCalibration(2).T), 1e-12);
    EXPECT_EQ(store->Add(MakeCalibration(3), MakeReport(true, 0.2))->value, 4);
  }
  // A temporary file left by an interrupted write still reserves its id.
  WriteText(dir + "/cal-000009.yaml.tmp-Ab12Cd", "partial");
  WriteText(dir + "/notes.txt", "not ours");
  {
    std::unique_ptr<CalibrationStore> store = OpenClean(dir);
    EXPECT_EQ(store->List().size(), 4u);
    EXPECT_EQ(store->Add(MakeCalibration(4), MakeReport(true, 0.2))->value, 10);
  }
}

TEST(CalibrationStore, PersistsTheActiveCalibration) {
  const std::string dir = testing::MakeTempDir("stevi-store");
  {
    std::unique_ptr<CalibrationStore> store = OpenClean(dir);
    ASSERT_TRUE(store->Add(MakeCalibration(0), MakeReport(true, 0.2)).ok());
    ASSERT_TRUE(store->Add(MakeCalibration(1), MakeReport(true, 0.2)).ok());
    const Status s = store->Activate(CalibrationId{2});
    ASSERT_TRUE(s.ok()) << s.error().message;
    EXPECT_EQ(store->ActiveId()->value, 2);
    EXPECT_EQ(ReadText(dir + "/active"), "cal-000002\n");
    const Result<StoredCalibration> active = store->Active();
    ASSERT_TRUE(active.ok());
    EXPECT_EQ(active->calibration.M1(0, 0), 521);
    EXPECT_EQ(store->Activate(CalibrationId{5}).error().code, ErrorCode::kNotFound);
    EXPECT_EQ(store->ActiveId()->value, 2);
  }
  std::unique_ptr<CalibrationStore> store = OpenClean(dir);
  ASSERT_TRUE(store->ActiveId().has_value());
  EXPECT_EQ(store->ActiveId()->value, 2);
  ASSERT_TRUE(store->Activate(CalibrationId{1}).ok());
  EXPECT_EQ(OpenClean(dir)->ActiveId()->value, 1);
}

TEST(CalibrationStore, StoresButRefusesToActivateAFailedCalibration) {
  const std::string dir = testing::MakeTempDir("stevi-store");
  std::unique_ptr<CalibrationStore> store = OpenClean(dir);
  ASSERT_TRUE(store->Add(MakeCalibration(0), MakeReport(true, 0.2)).ok());
  ASSERT_TRUE(store->Activate(CalibrationId{1}).ok());
  const Result<CalibrationId> failed = store->Add(MakeCalibration(1), MakeReport(false, 1.7));
  ASSERT_TRUE(failed.ok()) << failed.error().message;
  EXPECT_FALSE(store->List()[1].passed);
  EXPECT_EQ(store->Get(*failed)->report.failures[0].gate, "max_rms_px");

  const Status s = store->Activate(*failed);
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(s, IsError(ErrorCode::kFailedPrecondition));
  EXPECT_EQ(
      s.error().message,
      "cal-000002 failed its quality gates (stereo RMS reprojection error 1.700 px > 1.000 px "
      "(max_rms_px)); it can be inspected but not activated");
  EXPECT_EQ(store->ActiveId()->value, 1);
  EXPECT_EQ(ReadText(dir + "/active"), "cal-000001\n");
}

TEST(CalibrationStore, RefusesAnInvalidCalibration) {
  const std::string dir = testing::MakeTempDir("stevi-store");
  std::unique_ptr<CalibrationStore> store = OpenClean(dir);
  geometry::StereoCalibration bad = MakeCalibration(0);
  bad.M1(0, 0) = -5;
  const Result<CalibrationId> id = store->Add(bad, MakeReport(true, 0.2));
  ASSERT_FALSE(id.ok());
  EXPECT_THAT(
      id, IsError(ErrorCode::kInvalidArgument, HasSubstr("M1: focal lengths fx, fy must be > 0")));
  EXPECT_THAT(store->List(), IsEmpty());
  EXPECT_TRUE(fs::is_empty(dir));
}

TEST(CalibrationStore, OpensADamagedDirectoryAndFallsBackToTheLastGoodOne) {
  const std::string dir = testing::MakeTempDir("stevi-store");
  {
    std::unique_ptr<CalibrationStore> store = OpenClean(dir);
    ASSERT_TRUE(store->Add(MakeCalibration(0), MakeReport(true, 0.2)).ok());  // 1
    ASSERT_TRUE(
        store->Add(MakeCalibration(1), MakeReport(true, 0.2)).ok());  // 2: the last good one
    ASSERT_TRUE(store->Add(MakeCalibration(2), MakeReport(true, 0.2)).ok());  // 3: to be corrupted
    ASSERT_TRUE(
        store->Add(MakeCalibration(3), MakeReport(false, 1.7)).ok());  // 4: failed its gates
    ASSERT_TRUE(
        store->Add(MakeCalibration(4), MakeReport(true, 0.2)).ok());  // 5: report to be lost
    ASSERT_TRUE(store->Activate(CalibrationId{3}).ok());
  }
  // cal-000003.yaml: M1 becomes 3x2.
  std::string yaml = ReadText(dir + "/cal-000003.yaml");
  const std::size_t m1 = yaml.find("M1:");
  ASSERT_NE(m1, std::string::npos);
  yaml.replace(yaml.find("cols: 3", m1), 7, "cols: 2");
  WriteText(dir + "/cal-000003.yaml", yaml);
  fs::remove(dir + "/cal-000005.report.yaml");
  WriteText(dir + "/cal-000006.report.yaml", "orphan");

  Result<OpenedStore> opened = CalibrationStore::Open(dir);
  ASSERT_TRUE(opened.ok()) << opened.error().message;
  for (const std::string& p : opened->problems) std::printf("problem: %s\n", p.c_str());
  EXPECT_THAT(opened->problems,
              ElementsAre(HasSubstr("cal-000006.report.yaml: no calibration file beside it (an "
                                    "interrupted Add?); left out"),
                          HasSubstr("cal-000003.yaml: M1: expected a 3x3 matrix"),
                          "cal-000005.report.yaml: missing; cal-000005 is left out",
                          "active: points to cal-000003, which is unreadable; using cal-000002 "
                          "(the last good one)"));
  CalibrationStore& store = *opened->store;
  std::vector<int64_t> ids;
  for (const CalibrationSummary& s : store.List()) ids.push_back(s.id.value);
  EXPECT_THAT(ids, ElementsAre(1, 2, 4));
  EXPECT_EQ(store.ActiveId()->value, 2);
  EXPECT_EQ(store.Active()->calibration.M1(0, 0), 521);
  // Open() does not rewrite the active file; ids of unreadable files are not reused.
  EXPECT_EQ(ReadText(dir + "/active"), "cal-000003\n");
  EXPECT_EQ(store.Add(MakeCalibration(5), MakeReport(true, 0.2))->value, 7);

  // A dangling active id, pointing past every file: the fallback, and the id is never reused.
  WriteText(dir + "/active", "cal-000012\n");
  opened = CalibrationStore::Open(dir);
  ASSERT_TRUE(opened.ok());
  EXPECT_THAT(opened->problems,
              ::testing::Contains("active: points to cal-000012, which is missing (no "
                                  "cal-000012.yaml); using cal-000007 (the last good one)"));
  EXPECT_EQ(opened->store->ActiveId()->value, 7);
  EXPECT_EQ(opened->store->Add(MakeCalibration(6), MakeReport(true, 0.2))->value, 13);

  // An active file naming a calibration that failed its gates.
  WriteText(dir + "/active", "cal-000004");
  opened = CalibrationStore::Open(dir);
  EXPECT_THAT(opened->problems,
              ::testing::Contains("active: points to cal-000004, which failed its quality gates; "
                                  "using cal-000013 (the last good one)"));

  // A corrupt active file.
  WriteText(dir + "/active", std::string("\x01garbage", 8));
  opened = CalibrationStore::Open(dir);
  ASSERT_TRUE(opened.ok());
  EXPECT_THAT(opened->problems,
              ::testing::Contains("active: cannot read \"?garbage\" as a calibration id; using "
                                  "cal-000013 (the last good one)"));
  EXPECT_EQ(opened->store->ActiveId()->value, 13);
}

TEST(CalibrationStore, NoGoodCalibrationMeansNoneActive) {
  const std::string dir = testing::MakeTempDir("stevi-store");
  ASSERT_TRUE(OpenClean(dir)->Add(MakeCalibration(0), MakeReport(false, 2.0)).ok());
  WriteText(dir + "/active", "cal-000001\n");
  Result<OpenedStore> opened = CalibrationStore::Open(dir);
  ASSERT_TRUE(opened.ok());
  EXPECT_THAT(opened->problems, ElementsAre("active: points to cal-000001, which failed its "
                                            "quality gates; no calibration is active"));
  EXPECT_FALSE(opened->store->ActiveId().has_value());
  EXPECT_THAT(opened->store->Active(), IsError(ErrorCode::kFailedPrecondition));
}

TEST(CalibrationStore, RefusesAFileAsItsDirectory) {
  const std::string dir = testing::MakeTempDir("stevi-store");
  WriteText(dir + "/plain", "x");
  const Result<OpenedStore> opened = CalibrationStore::Open(dir + "/plain");
  ASSERT_FALSE(opened.ok());
  EXPECT_THAT(opened, IsError(ErrorCode::kInvalidArgument, HasSubstr("is not a directory")));
}

TEST(CalibrationStore, ConcurrentAddsGetDistinctIds) {
  const std::string dir = testing::MakeTempDir("stevi-store");
  std::unique_ptr<CalibrationStore> store = OpenClean(dir);
  std::vector<std::thread> threads;
  std::vector<std::vector<int64_t>> ids(4);
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      for (int i = 0; i < 5; ++i) {
        const Result<CalibrationId> id = store->Add(MakeCalibration(t), MakeReport(true, 0.2));
        if (id.ok()) ids[t].push_back(id->value);
        (void)store->List();
      }
    });
  }
  for (std::thread& t : threads) t.join();
  std::set<int64_t> all;
  for (const auto& v : ids) all.insert(v.begin(), v.end());
  EXPECT_EQ(all.size(), 20u);
  EXPECT_EQ(*all.rbegin(), 20);
  EXPECT_EQ(OpenClean(dir)->List().size(), 20u);
}

}  // namespace
}  // namespace stevi::calibration
