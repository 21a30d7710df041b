#include "tests/testing/real_pairs.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <opencv2/imgcodecs.hpp>

namespace stevi::testing {
namespace {

struct MiddleburyEntry {
  const char* name;
  const char* folder;
  const char* left;
  const char* right;
  const char* truth;
  double truth_scale;  // stored value / scale = disparity (PGM/PNG); 0 = PFM, in pixels
  const char* mask;    // non-occlusion mask, 255 = evaluated
};

constexpr MiddleburyEntry kMiddlebury[] = {
    {"tsukuba", "middlebury2001/tsukuba", "scene1.row3.col3.ppm", "scene1.row3.col4.ppm",
     "truedisp.row3.col3.pgm", 16.0, "nonocc.png"},
    {"venus", "middlebury2001/venus", "im2.ppm", "im6.ppm", "disp2.pgm", 8.0, "nonocc.png"},
    {"teddy", "middlebury2003/teddy", "im2.png", "im6.png", "disp2.png", 4.0, "nonocc.png"},
    {"cones", "middlebury2003/cones", "im2.png", "im6.png", "disp2.png", 4.0, "nonocc.png"},
    {"motorcycle", "middlebury2014/motorcycle_quarter", "im0.png", "im1.png", "disp0GT.pfm", 0.0,
     "mask0nocc.png"},
};

struct KittiEntry {
  const char* name;
  const char* folder;
  const char* truth_dir;
};

constexpr KittiEntry kKitti[] = {
    {"000000_10", "kitti2015/training", "disp_occ_0"},
    {"000001_10", "kitti2015/training", "disp_occ_0"},
    {"000002_10", "kitti2015/training", "disp_occ_0"},
    {"000005_10", "kitti2015/more", "disp_gt"},
    {"000046_10", "kitti2015/more", "disp_gt"},
};

bool Exists(const std::string& path, std::string& problem) {
  if (std::filesystem::exists(path)) return true;
  problem = "not found: " + path;
  return false;
}

// Middlebury 2014 calib.txt: cam0=[f 0 cx; 0 f cy; 0 0 1], doffs=, baseline= (mm).
bool ReadMiddlebury2014Calib(const std::string& path, RealPair& pair, std::string& problem) {
  std::ifstream in(path);
  std::string line;
  bool cam0 = false, doffs = false, baseline = false;
  while (std::getline(in, line)) {
    double f = 0, cx = 0, cy = 0, value = 0;
    if (std::sscanf(line.c_str(), "cam0=[%lf %*f %lf; %*f %*f %lf", &f, &cx, &cy) == 3) {
      pair.f_px = f;
      pair.cx = cx;
      pair.cy = cy;
      cam0 = true;
    } else if (std::sscanf(line.c_str(), "doffs=%lf", &value) == 1) {
      pair.doffs = value;
      doffs = true;
    } else if (std::sscanf(line.c_str(), "baseline=%lf", &value) == 1) {
      pair.baseline_m = value / 1000.0;
      baseline = true;
    }
  }
  if (!cam0 || !doffs || !baseline) {
    problem = path + ": no cam0, doffs or baseline";
    return false;
  }
  return true;
}

// KITTI calib_cam_to_cam.txt: P_rect_02 and P_rect_03 give f, the principal point and the baseline
// ((P02[0][3] - P03[0][3]) / f).
bool ReadKittiCalib(const std::string& path, RealPair& pair, std::string& problem) {
  std::ifstream in(path);
  std::string line;
  double p2[12] = {}, p3[12] = {};
  bool have2 = false, have3 = false;
  while (std::getline(in, line)) {
    const bool is2 = line.rfind("P_rect_02:", 0) == 0, is3 = line.rfind("P_rect_03:", 0) == 0;
    if (!is2 && !is3) continue;
    std::istringstream values(line.substr(10));
    double* p = is2 ? p2 : p3;
    int n = 0;
    while (n < 12 && values >> p[n]) ++n;
    if (n == 12) (is2 ? have2 : have3) = true;
  }
  if (!have2 || !have3 || p2[0] <= 0) {
    problem = path + ": no P_rect_02 / P_rect_03";
    return false;
  }
  pair.f_px = p2[0];
  pair.cx = p2[2];
  pair.cy = p2[6];
  pair.baseline_m = (p2[3] - p3[3]) / p2[0];
  pair.doffs = 0;
  return true;
}

std::optional<RealPair> LoadMiddlebury(const std::string& data_dir, const MiddleburyEntry& e,
                                       std::string& problem) {
  RealPair pair;
  pair.name = e.name;
  pair.folder = data_dir + "/" + e.folder;
  const std::string dir = pair.folder + "/";
  for (const char* file : {e.left, e.right, e.truth, e.mask}) {
    if (!Exists(dir + file, problem)) return std::nullopt;
  }
  pair.left = cv::imread(dir + e.left, cv::IMREAD_GRAYSCALE);
  pair.right = cv::imread(dir + e.right, cv::IMREAD_GRAYSCALE);
  // Some masks are palette PNGs: IMREAD_GRAYSCALE gives the grey level, 255 = evaluated (the 2014
  // mask has 128 for occluded).
  const cv::Mat mask = cv::imread(dir + e.mask, cv::IMREAD_GRAYSCALE);
  if (e.truth_scale > 0) {
    const cv::Mat truth = cv::imread(dir + e.truth, cv::IMREAD_GRAYSCALE);
    if (!truth.empty()) truth.convertTo(pair.truth_px, CV_32F, 1.0 / e.truth_scale);
  } else {
    pair.truth_px = ReadPfm(dir + e.truth);
    // inf = unknown.
    for (float& v : pair.truth_px) {
      if (!std::isfinite(v) || v < 0) v = 0;
    }
  }
  if (pair.left.empty() || pair.right.empty() || pair.truth_px.empty() || mask.empty() ||
      pair.truth_px.size() != pair.left.size() || mask.size() != pair.left.size()) {
    problem = dir + ": unreadable or mismatched images";
    return std::nullopt;
  }
  pair.evaluated = (mask > 128) & (pair.truth_px > 0);
  pair.nonocc_mask = true;
  if (e.truth_scale > 0) {
    pair.f_px = pair.left.cols;
    pair.baseline_m = 0.1;
    pair.cx = (pair.left.cols - 1) / 2.0;
    pair.cy = (pair.left.rows - 1) / 2.0;
  } else {
    if (!ReadMiddlebury2014Calib(dir + "calib.txt", pair, problem)) return std::nullopt;
    pair.rig_known = true;
  }
  return pair;
}

std::optional<RealPair> LoadKitti(const std::string& data_dir, const KittiEntry& e,
                                  std::string& problem) {
  RealPair pair;
  pair.name = std::string("kitti-") + e.name;
  pair.folder = data_dir + "/" + e.folder;
  pair.kitti = true;
  const std::string png = std::string(e.name) + ".png";
  const std::string left = pair.folder + "/image_2/" + png, right = pair.folder + "/image_3/" + png,
                    truth = pair.folder + "/" + e.truth_dir + "/" + png,
                    calib = data_dir + "/kitti2015/raw_calib_2011_09_26/calib_cam_to_cam.txt";
  for (const std::string& file : {left, right, truth, calib}) {
    if (!Exists(file, problem)) return std::nullopt;
  }
  pair.left = cv::imread(left, cv::IMREAD_GRAYSCALE);
  pair.right = cv::imread(right, cv::IMREAD_GRAYSCALE);
  const cv::Mat raw = cv::imread(truth, cv::IMREAD_ANYDEPTH);
  if (pair.left.empty() || pair.right.empty() || raw.type() != CV_16UC1 ||
      raw.size() != pair.left.size() || pair.right.size() != pair.left.size()) {
    problem = pair.folder + ": unreadable or mismatched images for " + e.name;
    return std::nullopt;
  }
  raw.convertTo(pair.truth_px, CV_32F, 1.0 / 256.0);  // 0 stays 0 = unknown
  pair.evaluated = pair.truth_px > 0;
  if (!ReadKittiCalib(calib, pair, problem)) return std::nullopt;
  pair.rig_known = true;
  return pair;
}

}  // namespace

std::vector<std::string> MiddleburyPairNames(bool with_2014) {
  std::vector<std::string> names;
  for (const MiddleburyEntry& e : kMiddlebury) {
    if (e.truth_scale > 0 || with_2014) names.push_back(e.name);
  }
  return names;
}

std::vector<std::string> KittiPairNames() {
  std::vector<std::string> names;
  for (const KittiEntry& e : kKitti) names.push_back(std::string("kitti-") + e.name);
  return names;
}

std::optional<RealPair> LoadRealPair(const std::string& data_dir, const std::string& name,
                                     std::string& problem) {
  for (const MiddleburyEntry& e : kMiddlebury) {
    if (name == e.name) return LoadMiddlebury(data_dir, e, problem);
  }
  for (const KittiEntry& e : kKitti) {
    if (name == std::string("kitti-") + e.name) return LoadKitti(data_dir, e, problem);
  }
  problem = "unknown pair '" + name + "'";
  return std::nullopt;
}

std::vector<RealPair> LoadRealPairs(const std::string& data_dir,
                                    const std::vector<std::string>& names, std::string& problem) {
  std::vector<RealPair> pairs;
  for (const std::string& name : names) {
    std::optional<RealPair> pair = LoadRealPair(data_dir, name, problem);
    if (!pair) return {};
    pairs.push_back(std::move(*pair));
  }
  return pairs;
}

cv::Mat1f ReadPfm(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string magic;
  int width = 0, height = 0;
  double scale = 0;
  if (!(in >> magic >> width >> height >> scale) || magic != "Pf" || width <= 0 || height <= 0) {
    return {};
  }
  in.get();                  // the single whitespace character after the scale
  if (scale > 0) return {};  // big-endian: not written by Middlebury, not handled
  cv::Mat1f out(height, width);
  for (int y = height - 1; y >= 0; --y) {  // rows bottom to top
    in.read(reinterpret_cast<char*>(out.ptr<float>(y)),
            static_cast<std::streamsize>(width * sizeof(float)));
  }
  if (!in) return {};
  return out;
}

void TruthOnGrid(const RealPair& pair, int binning, cv::Mat1f& truth_px, cv::Mat1b& evaluated) {
  if (binning <= 1) {
    truth_px = pair.truth_px;
    evaluated = pair.evaluated;
    return;
  }
  const int rows = pair.truth_px.rows / binning, cols = pair.truth_px.cols / binning;
  truth_px.create(rows, cols);
  evaluated.create(rows, cols);
  std::vector<float> values;
  for (int j = 0; j < rows; ++j) {
    for (int i = 0; i < cols; ++i) {
      values.clear();
      for (int y = j * binning; y < (j + 1) * binning; ++y) {
        for (int x = i * binning; x < (i + 1) * binning; ++x) {
          if (pair.evaluated(y, x)) values.push_back(pair.truth_px(y, x));
        }
      }
      if (2 * values.size() < static_cast<size_t>(binning * binning)) {
        truth_px(j, i) = 0;
        evaluated(j, i) = 0;
        continue;
      }
      // Median (the mean of the two middle values for an even count).
      const size_t n = values.size(), mid = n / 2;
      std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(mid),
                       values.end());
      float median = values[mid];
      if (n % 2 == 0) {
        median =
            0.5f * (median + *std::max_element(values.begin(),
                                               values.begin() + static_cast<std::ptrdiff_t>(mid)));
      }
      truth_px(j, i) = median;
      evaluated(j, i) = 255;
    }
  }
}

DisparityScore ScoreDisparity(const stereo::DisparityMap& disparity, int binning,
                              const RealPair& pair) {
  cv::Mat1f truth;
  cv::Mat1b evaluated;
  TruthOnGrid(pair, binning, truth, evaluated);
  DisparityScore s;
  const int rows = std::min(truth.rows, disparity.fixed.rows);
  const int cols = std::min(truth.cols, disparity.fixed.cols);
  for (int y = 0; y < rows; ++y) {
    for (int x = 0; x < cols; ++x) {
      if (!evaluated(y, x)) continue;
      ++s.evaluated;
      const double t = truth(y, x);
      const std::optional<float> d = disparity.At(x, y);
      if (!d) {
        ++s.bad1_raw;
        ++s.bad3_raw;
        ++s.d1_raw;
        s.abs_sum_raw += t;
        continue;
      }
      ++s.matched;
      const double error = std::abs(static_cast<double>(*d) * binning - t);
      const bool bad1 = error > 1.0, bad3 = error > 3.0, d1 = bad3 && error > 0.05 * t;
      s.bad1_raw += bad1;
      s.bad3_raw += bad3;
      s.d1_raw += d1;
      s.bad1_matched += bad1;
      s.bad3_matched += bad3;
      s.d1_matched += d1;
      s.abs_sum_matched += error;
      s.abs_sum_raw += error;
    }
  }
  return s;
}

}  // namespace stevi::testing
