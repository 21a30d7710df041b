#include "core/calibration/chessboard.h"

#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/calibration/chessboard_render.h"
#include "core/calibration/image_header.h"
#include "tests/core/calibration/synthetic_rig.h"
#include "tests/testing/status_matchers.h"

using stevi::testing::IsError;

namespace stevi::calibration {
namespace {

using ::testing::HasSubstr;
using testing::TestBoard;
using testing::TruthRig;

std::string Encode(const cv::Mat& image, const std::string& ext,
                   const std::vector<int>& params = {}) {
  std::vector<uchar> bytes;
  EXPECT_TRUE(cv::imencode(ext, image, bytes, params));
  return std::string(bytes.begin(), bytes.end());
}

cv::Mat Noise(cv::Size size, int type, uint64_t seed) {
  cv::Mat m(size, type);
  cv::RNG rng(seed);
  rng.fill(m, cv::RNG::UNIFORM, 0, 256);
  return m;
}

// A PNG signature and IHDR chunk announcing width x height, with no image data after it.
std::string PngHeaderOnly(uint32_t width, uint32_t height) {
  std::string s = std::string("\x89PNG\r\n\x1a\n", 8);
  auto be32 = [&](uint32_t v) {
    for (int shift = 24; shift >= 0; shift -= 8)
      s.push_back(static_cast<char>((v >> shift) & 0xFF));
  };
  be32(13);
  s += "IHDR";
  be32(width);
  be32(height);
  s += std::string("\x08\x00\x00\x00\x00", 5);  // 8-bit grey, no interlace
  be32(0);                                      // CRC (not checked by the header reader)
  return s;
}

// A JPEG: SOI, an APP0 segment, then a baseline SOF0 announcing width x height, and nothing more.
std::string JpegHeaderOnly(uint16_t width, uint16_t height) {
  std::string s("\xFF\xD8", 2);
  s += std::string("\xFF\xE0\x00\x10JFIF\x00\x01\x01\x00\x00\x01\x00\x01\x00\x00", 18);
  s += std::string("\xFF\xC0\x00\x0B\x08", 5);
  s.push_back(static_cast<char>(height >> 8));
  s.push_back(static_cast<char>(height & 0xFF));
  s.push_back(static_cast<char>(width >> 8));
  s.push_back(static_cast<char>(width & 0xFF));
  s += std::string("\x01\x01\x11\x00", 4);
  return s;
}

TEST(ImageHeaderSize, ReadsPngAndJpegWrittenByOpenCv) {
  const struct {
    cv::Size size;
    int type;
    std::string ext;
    std::vector<int> params;
  } cases[] = {
      {{37, 23}, CV_8UC1, ".png", {}},
      {{640, 481}, CV_8UC3, ".png", {}},
      {{1, 1}, CV_16UC1, ".png", {}},
      {{640, 512}, CV_8UC1, ".jpg", {}},
      {{333, 77}, CV_8UC3, ".jpg", {cv::IMWRITE_JPEG_QUALITY, 60}},
      {{200, 150}, CV_8UC3, ".jpg", {cv::IMWRITE_JPEG_PROGRESSIVE, 1}},
      {{65, 4097}, CV_8UC1, ".jpg", {cv::IMWRITE_JPEG_OPTIMIZE, 1}},
  };
  for (const auto& c : cases) {
    const std::string bytes = Encode(Noise(c.size, c.type, 7), c.ext, c.params);
    const Result<cv::Size> size = ImageHeaderSize(bytes);
    ASSERT_TRUE(size.ok()) << c.ext << " " << c.size << ": " << size.error().message;
    EXPECT_EQ(*size, c.size) << c.ext;
  }
}

TEST(ImageHeaderSize, ReadsHandMadeHeadersWithoutImageData) {
  EXPECT_EQ(*ImageHeaderSize(PngHeaderOnly(100000, 3)), cv::Size(100000, 3));
  EXPECT_EQ(*ImageHeaderSize(JpegHeaderOnly(60000, 50000)), cv::Size(60000, 50000));
}

TEST(ImageHeaderSize, RefusesTruncatedAndGarbageBytes) {
  const std::string png = Encode(Noise({64, 48}, CV_8UC1, 1), ".png");
  const std::string jpg = Encode(Noise({64, 48}, CV_8UC1, 1), ".jpg");
  const struct {
    std::string bytes;
    std::string message;
  } cases[] = {
      {"", "empty image data"},
      {"hello, world", "not a PNG or JPEG image (starts with 68 65 6c 6c)"},
      {"GIF89a\x01\x00\x01\x00", "not a PNG or JPEG image (starts with 47 49 46 38)"},
      {png.substr(0, 6), "truncated PNG header"},
      {png.substr(0, 20), "truncated PNG header (20 bytes"},
      {jpg.substr(0, 2), "truncated JPEG"},
      {jpg.substr(0, 20), "truncated JPEG"},  // SOI and the JFIF APP0 segment only
      {jpg.substr(0, 5), "truncated JPEG: a segment length is cut off"},
      {std::string("\xFF\xD8\xFF\xD9", 4), "ends (EOI) before a frame header"},
      {std::string("\xFF\xD8\x00\x00", 4), "expected a marker at byte 2"},
      {std::string("\xFF\xD8\xFF\xDA\x00\x08", 6), "image data (SOS) before a frame header"},
      {JpegHeaderOnly(640, 0), "height is given later (DNL marker)"},
      {JpegHeaderOnly(640, 480).substr(0, 26), "truncated JPEG frame header"},
      {PngHeaderOnly(0, 10), "out of range"},
      {PngHeaderOnly(3000000000u, 10), "out of range"},
  };
  for (const auto& c : cases) {
    const Result<cv::Size> size = ImageHeaderSize(c.bytes);
    ASSERT_FALSE(size.ok()) << "accepted: " << c.message;
    EXPECT_THAT(size, IsError(ErrorCode::kInvalidArgument, HasSubstr(c.message)));
  }
  // A PNG whose first chunk is not IHDR.
  std::string bad_chunk = png;
  bad_chunk[12] = 'X';
  EXPECT_THAT(ImageHeaderSize(bad_chunk).error().message, HasSubstr("not a 13-byte IHDR"));
}

TEST(DecodeGreyImage, DecodesPngExactlyAndJpegToGrey) {
  const cv::Mat grey = Noise({61, 43}, CV_8UC1, 3);
  const std::string png = Encode(grey, ".png");
  const Result<cv::Mat> decoded = DecodeGreyImage(
      std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(png.data()), png.size()),
      {4096, 4096});
  ASSERT_TRUE(decoded.ok()) << decoded.error().message;
  EXPECT_EQ(decoded->type(), CV_8UC1);
  EXPECT_EQ(cv::norm(*decoded, grey, cv::NORM_INF), 0);

  const std::vector<uchar> jpg_bytes = [] {
    std::vector<uchar> b;
    cv::imencode(".jpg", Noise({80, 60}, CV_8UC3, 4), b);
    return b;
  }();
  const Result<cv::Mat> jpg = DecodeGreyImage(jpg_bytes, {4096, 4096});
  ASSERT_TRUE(jpg.ok()) << jpg.error().message;
  EXPECT_EQ(jpg->type(), CV_8UC1);
  EXPECT_EQ(jpg->size(), cv::Size(80, 60));
}

TEST(DecodeGreyImage, RefusesOversizedHeadersWithoutDecoding) {
  // Only a header: decoding would fail, so kResourceExhausted proves nothing was decoded.
  for (const std::string& bytes : {PngHeaderOnly(5000, 5000), JpegHeaderOnly(4097, 100)}) {
    const Result<cv::Mat> decoded = DecodeGreyImage(
        std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size()),
        {4096, 4096});
    ASSERT_FALSE(decoded.ok());
    EXPECT_THAT(decoded, IsError(ErrorCode::kResourceExhausted));
    EXPECT_THAT(decoded.error().message,
                HasSubstr("exceeds the maximum of 4096x4096; not decoded"));
  }
  // A real image one pixel over a smaller limit.
  const std::string png = Encode(Noise({101, 50}, CV_8UC1, 5), ".png");
  const auto span =
      std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(png.data()), png.size());
  EXPECT_EQ(DecodeGreyImage(span, {100, 100}).error().code, ErrorCode::kResourceExhausted);
  EXPECT_TRUE(DecodeGreyImage(span, {101, 50}).ok());
}

TEST(DecodeGreyImage, RefusesCorruptData) {
  std::string png = Encode(Noise({64, 64}, CV_8UC1, 6), ".png");
  for (std::size_t i = 40; i < png.size() - 12; i += 3) png[i] = static_cast<char>(png[i] ^ 0x5A);
  const Result<cv::Mat> decoded = DecodeGreyImage(
      std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(png.data()), png.size()),
      {4096, 4096});
  ASSERT_FALSE(decoded.ok());
  EXPECT_THAT(decoded, IsError(ErrorCode::kInvalidArgument, HasSubstr("cannot decode the image")));
}

TEST(BoardSpec, ValidatesAndListsObjectPoints) {
  EXPECT_THAT(TestBoard().Validate(), ::testing::IsEmpty());
  const std::vector<cv::Point3f> points = TestBoard().ObjectPoints();
  ASSERT_EQ(points.size(), 54u);
  EXPECT_EQ(points[1], cv::Point3f(0.03f, 0, 0));  // along a row first
  EXPECT_EQ(points[9], cv::Point3f(0, 0.03f, 0));  // then the next row
  EXPECT_NEAR(points.back().x, 0.24, 1e-6);
  EXPECT_NEAR(points.back().y, 0.15, 1e-6);

  const std::vector<std::string> problems = BoardSpec{6, 6, -0.01}.Validate();
  EXPECT_THAT(problems, ::testing::Contains(HasSubstr("columns, rows: must differ")));
  EXPECT_THAT(problems,
              ::testing::Contains(HasSubstr("square_m: must be in (0, 10] metres (got -0.01)")));
  EXPECT_THAT((BoardSpec{2, 6, 0.02}.Validate()),
              ::testing::Contains(HasSubstr("columns: must be in [3, 100] (got 2)")));
}

// Largest distance between detected corners and the truth, index by index.
double WorstError(const std::vector<cv::Point2f>& found, const std::vector<cv::Point2f>& truth) {
  EXPECT_EQ(found.size(), truth.size());
  double worst = 0;
  for (std::size_t i = 0; i < std::min(found.size(), truth.size()); ++i) {
    worst = std::max(worst, cv::norm(found[i] - truth[i]));
  }
  return worst;
}

TEST(DetectChessboard, FindsRenderedCornersWithinATenthOfAPixel) {
  const auto rig = TruthRig();
  const BoardSpec board = TestBoard();
  Result<ChessboardRenderer> renderer = ChessboardRenderer::Create(rig, board, testing::kImageSize);
  ASSERT_TRUE(renderer.ok()) << renderer.error().message;
  Result<std::vector<cv::Affine3d>> poses =
      GenerateBoardPoses(rig, board, testing::kImageSize, 6, 11);
  ASSERT_TRUE(poses.ok()) << poses.error().message;
  // Also a board turned upside down: the detectors number it from the other end, and the
  // numbering rule must bring corner 0 back to the board's own corner 0.
  poses->push_back(cv::Affine3d(cv::Vec3d(0.2, -0.1, CV_PI), cv::Vec3d(0.12, 0.08, 0.55)));

  const DetectionOptions variants[] = {
      {.detector = CornerDetector::kSectorBasedThenClassic},
      {.detector = CornerDetector::kSectorBased},
      {.detector = CornerDetector::kClassic},
      {.detector = CornerDetector::kSectorBased, .refinement = CornerRefinement::kCornerSubPix},
  };
  double mean_saddle = 0, mean_subpix = 0;
  for (const DetectionOptions& options : variants) {
    const bool saddle = options.refinement == CornerRefinement::kSaddlePoint;
    const std::string name = std::string(CornerDetectorName(options.detector)) + " + " +
                             std::string(CornerRefinementName(options.refinement));
    double worst = 0, sum = 0;
    int n = 0;
    for (const cv::Affine3d& pose : *poses) {
      const RenderedPair images = renderer->Render(pose);
      const ProjectedBoard truth = ProjectChessboard(rig, board, pose);
      for (const auto& [image, expected] :
           {std::pair{&images.left, &truth.left}, {&images.right, &truth.right}}) {
        const Result<std::vector<cv::Point2f>> corners = DetectChessboard(*image, board, options);
        ASSERT_TRUE(corners.ok()) << name << ": " << corners.error().message;
        const double e = WorstError(*corners, *expected);
        // cornerSubPix alone is measured, not held to the tenth of a pixel (see the README).
        EXPECT_LT(e, saddle ? 0.1 : 0.3) << name;
        worst = std::max(worst, e);
        for (std::size_t i = 0; i < corners->size(); ++i)
          sum += cv::norm((*corners)[i] - (*expected)[i]);
        n += static_cast<int>(corners->size());
      }
    }
    std::printf("%-40s corner error over %zu views: mean %.4f px, worst %.4f px\n", name.c_str(),
                2 * poses->size(), sum / n, worst);
    (saddle ? mean_saddle : mean_subpix) = sum / n;
  }
  EXPECT_LT(mean_saddle, 0.03);
  EXPECT_LT(mean_saddle, 0.5 * mean_subpix);
}

TEST(DetectChessboard, ReportsNoBoardAndWrongSizes) {
  const auto rig = TruthRig();
  const BoardSpec board = TestBoard();
  const cv::Affine3d pose(cv::Vec3d(0.1, 0.2, 0.05), cv::Vec3d(-0.1, -0.07, 0.6));
  const Result<RenderedPair> images = RenderChessboardPair(rig, board, pose, testing::kImageSize);
  ASSERT_TRUE(images.ok()) << images.error().message;
  ASSERT_TRUE(DetectChessboard(images->left, board).ok());

  const cv::Mat blank(testing::kImageSize, CV_8UC1, cv::Scalar(128));
  const Result<std::vector<cv::Point2f>> none = DetectChessboard(blank, board);
  ASSERT_FALSE(none.ok());
  EXPECT_THAT(none,
              IsError(ErrorCode::kNotFound, HasSubstr("no board of 9x6 inner corners found")));

  for (const BoardSpec wrong :
       {BoardSpec{10, 6, 0.03}, BoardSpec{9, 7, 0.03}, BoardSpec{11, 8, 0.03}}) {
    const Result<std::vector<cv::Point2f>> found = DetectChessboard(images->left, wrong);
    ASSERT_FALSE(found.ok()) << wrong.Name();
    EXPECT_THAT(found, IsError(ErrorCode::kNotFound));
  }

  const Result<std::vector<cv::Point2f>> colour = DetectChessboard(cv::Mat(20, 20, CV_8UC3), board);
  ASSERT_FALSE(colour.ok());
  EXPECT_THAT(colour, IsError(ErrorCode::kInvalidArgument));
  EXPECT_THAT(colour.error().message,
              HasSubstr("expected a non-empty 8-bit grey image (CV_8UC1), got CV_8UC3"));
  EXPECT_EQ(DetectChessboard(images->left, BoardSpec{5, 5, 0.03}).error().code,
            ErrorCode::kInvalidArgument);
}

TEST(ChessboardRenderer, AntiAliasesAndAppliesTheLens) {
  const auto rig = TruthRig();
  const BoardSpec board = TestBoard();
  const cv::Affine3d pose(cv::Vec3d(0, 0, 0), cv::Vec3d(-0.12, -0.075, 0.7));
  const Result<RenderedPair> images = RenderChessboardPair(rig, board, pose, testing::kImageSize);
  ASSERT_TRUE(images.ok());
  // Levels: dark squares, light squares and margin, background, and anti-aliased edges between.
  double lo, hi;
  cv::minMaxLoc(images->left, &lo, &hi);
  EXPECT_EQ(lo, 30);
  EXPECT_EQ(hi, 225);
  const cv::Mat edges = (images->left > 31) & (images->left < 224) & (images->left != 110);
  EXPECT_GT(cv::countNonZero(edges), 500);
  // The centre of the square between corners 0, 1, 9 and 10 is dark, the next one light, and the
  // image corner (off the board) is background.
  const ProjectedBoard truth = ProjectChessboard(rig, board, pose);
  const cv::Point2f dark_centre =
      (truth.left[0] + truth.left[1] + truth.left[9] + truth.left[10]) * 0.25f;
  const cv::Point2f light_centre =
      (truth.left[1] + truth.left[2] + truth.left[10] + truth.left[11]) * 0.25f;
  EXPECT_EQ(images->left(cvRound(dark_centre.y), cvRound(dark_centre.x)), 30);
  EXPECT_EQ(images->left(cvRound(light_centre.y), cvRound(light_centre.x)), 225);
  EXPECT_EQ(images->left(0, 0), 110);

  const Result<RenderedPair> bad =
      RenderChessboardPair(rig, BoardSpec{9, 6, 0}, pose, {0, 10}, {.supersampling = 0});
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.error().message, HasSubstr("board.square_m"));
  EXPECT_THAT(bad.error().message, HasSubstr("image_size"));
  EXPECT_THAT(bad.error().message, HasSubstr("options.supersampling"));
}

TEST(GenerateBoardPoses, IsDeterministicVariedAndInViewOfBothCameras) {
  const auto rig = TruthRig();
  const BoardSpec board = TestBoard();
  const Result<std::vector<cv::Affine3d>> a =
      GenerateBoardPoses(rig, board, testing::kImageSize, 18, 42);
  const Result<std::vector<cv::Affine3d>> b =
      GenerateBoardPoses(rig, board, testing::kImageSize, 18, 42);
  const Result<std::vector<cv::Affine3d>> c =
      GenerateBoardPoses(rig, board, testing::kImageSize, 18, 43);
  ASSERT_TRUE(a.ok() && b.ok() && c.ok());
  ASSERT_EQ(a->size(), 18u);
  double max_tilt = 0, differs = 0;
  float min_x = 1e9f, max_x = 0, min_y = 1e9f, max_y = 0;
  for (std::size_t i = 0; i < a->size(); ++i) {
    EXPECT_EQ(cv::norm((*a)[i].matrix, (*b)[i].matrix, cv::NORM_INF), 0) << "pose " << i;
    differs = std::max(differs, cv::norm((*a)[i].matrix, (*c)[i].matrix, cv::NORM_INF));
    // The board normal's angle to the optical axis.
    const cv::Vec3d normal = (*a)[i].rotation() * cv::Vec3d(0, 0, 1);
    max_tilt = std::max(max_tilt, std::acos(std::abs(normal[2])) * 180 / CV_PI);
    const ProjectedBoard projected = ProjectChessboard(rig, board, (*a)[i]);
    for (const auto* view : {&projected.left, &projected.right}) {
      for (const cv::Point2f& p : *view) {
        EXPECT_TRUE(p.x > 0 && p.y > 0 && p.x < 639 && p.y < 479)
            << "pose " << i << " corner " << p;
      }
    }
    const cv::Rect box = cv::boundingRect(projected.left);
    min_x = std::min(min_x, static_cast<float>(box.x));
    max_x = std::max(max_x, static_cast<float>(box.br().x));
    min_y = std::min(min_y, static_cast<float>(box.y));
    max_y = std::max(max_y, static_cast<float>(box.br().y));
  }
  EXPECT_GT(differs, 0.01);
  EXPECT_LE(max_tilt, 30 * std::sqrt(2.0) + 0.1);
  EXPECT_GT(max_tilt, 15);
  // The boards reach out over the image as far as they can: the inner corners stay about two
  // squares (the margin, then the outer squares) from every edge, and on the left also out of the
  // ~100 px strip the right camera does not see at half a metre. That leaves about 380 x 330 px.
  std::printf("left corners span x %.0f..%.0f, y %.0f..%.0f\n", min_x, max_x, min_y, max_y);
  EXPECT_GT(max_x - min_x, 0.55 * 640);
  EXPECT_GT(max_y - min_y, 0.65 * 480);

  const Result<std::vector<cv::Affine3d>> impossible =
      GenerateBoardPoses(rig, BoardSpec{9, 6, 0.03}, testing::kImageSize, 1, 1,
                         {.min_width_fraction = 1.0, .max_width_fraction = 1.0});
  ASSERT_FALSE(impossible.ok());
  EXPECT_THAT(impossible, IsError(ErrorCode::kOutOfRange));
}

}  // namespace
}  // namespace stevi::calibration
