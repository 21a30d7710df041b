#include "core/tracking/hungarian.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <utility>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace stevi::tracking {
namespace {

using ::testing::Each;
using ::testing::Eq;
using ::testing::SizeIs;

// The best assignment by exhaustive search, scored lexicographically: first the number of
// forbidden pairs (cost >= kForbiddenCost), then the sum of the allowed costs. This is the
// documented meaning of the solver's answer, computed without relying on kForbiddenCost's size.
struct Score {
  int forbidden = 0;
  double allowed_sum = 0;
};

// Explores every injective map of the smaller side into the larger one.
void Search(const Eigen::MatrixXd& cost, bool transposed, int i, std::vector<char>& used,
            Score current, Score& best) {
  const int n = transposed ? static_cast<int>(cost.cols()) : static_cast<int>(cost.rows());
  const int m = transposed ? static_cast<int>(cost.rows()) : static_cast<int>(cost.cols());
  if (i == n) {
    if (current.forbidden < best.forbidden ||
        (current.forbidden == best.forbidden && current.allowed_sum < best.allowed_sum)) {
      best = current;
    }
    return;
  }
  for (int j = 0; j < m; ++j) {
    if (used[j]) continue;
    const double c = transposed ? cost(j, i) : cost(i, j);
    Score next = current;
    if (c >= kForbiddenCost) {
      ++next.forbidden;
    } else {
      next.allowed_sum += c;
    }
    used[j] = 1;
    Search(cost, transposed, i + 1, used, next, best);
    used[j] = 0;
  }
}

Score BruteForce(const Eigen::MatrixXd& cost) {
  const bool transposed = cost.rows() > cost.cols();
  std::vector<char> used(std::max(cost.rows(), cost.cols()), 0);
  Score best{std::numeric_limits<int>::max(), std::numeric_limits<double>::infinity()};
  Search(cost, transposed, 0, used, Score{}, best);
  return best;
}

// Checks that `row_to_col` is a maximum-cardinality matching of `cost` and returns its score.
Score CheckAndScore(const Eigen::MatrixXd& cost, const std::vector<int>& row_to_col) {
  EXPECT_EQ(static_cast<int>(row_to_col.size()), cost.rows());
  std::vector<char> taken(cost.cols(), 0);
  int assigned = 0;
  Score score;
  for (int i = 0; i < static_cast<int>(row_to_col.size()); ++i) {
    const int j = row_to_col[i];
    if (j == -1) continue;
    EXPECT_GE(j, 0);
    EXPECT_LT(j, cost.cols());
    if (j < 0 || j >= cost.cols()) continue;
    EXPECT_FALSE(taken[j]) << "column " << j << " assigned twice";
    taken[j] = 1;
    ++assigned;
    if (cost(i, j) >= kForbiddenCost) {
      ++score.forbidden;
    } else {
      score.allowed_sum += cost(i, j);
    }
  }
  EXPECT_EQ(assigned, std::min(cost.rows(), cost.cols()));
  return score;
}

enum class Kind { kReal, kSmallIntegers, kWithForbidden, kWithInfinity };

Eigen::MatrixXd RandomCost(int rows, int cols, Kind kind, std::mt19937& rng) {
  std::uniform_real_distribution<double> real(0.0, 100.0);
  std::uniform_int_distribution<int> small(0, 4);
  std::bernoulli_distribution forbid(0.35);
  Eigen::MatrixXd cost(rows, cols);
  for (int i = 0; i < rows; ++i) {
    for (int j = 0; j < cols; ++j) {
      switch (kind) {
        case Kind::kReal: cost(i, j) = real(rng); break;
        case Kind::kSmallIntegers: cost(i, j) = small(rng); break;  // many ties
        case Kind::kWithForbidden: cost(i, j) = forbid(rng) ? kForbiddenCost : real(rng); break;
        case Kind::kWithInfinity:
          cost(i, j) = forbid(rng) ? std::numeric_limits<double>::infinity() : real(rng);
          break;
      }
    }
  }
  return cost;
}

TEST(SolveAssignment, MatchesBruteForceOnRandomMatricesUpTo8x8) {
  std::mt19937 rng(20240611);
  AssignmentSolver reused;  // one solver across every size: its buffers must not leak state
  int cases = 0;
  for (Kind kind : {Kind::kReal, Kind::kSmallIntegers, Kind::kWithForbidden, Kind::kWithInfinity}) {
    for (int rows = 1; rows <= 8; ++rows) {
      for (int cols = 1; cols <= 8; ++cols) {
        // The 8x8 and 7x8 searches are the slow ones; fewer trials there.
        const int trials = rows * cols >= 49 ? 2 : 6;
        for (int trial = 0; trial < trials; ++trial) {
          const Eigen::MatrixXd cost = RandomCost(rows, cols, kind, rng);
          std::vector<int> row_to_col;
          reused.Solve(cost, row_to_col);
          const Score got = CheckAndScore(cost, row_to_col);
          const Score want = BruteForce(cost);
          EXPECT_EQ(got.forbidden, want.forbidden)
              << rows << "x" << cols << " kind " << static_cast<int>(kind) << " trial " << trial;
          EXPECT_NEAR(got.allowed_sum, want.allowed_sum, 1e-6)
              << rows << "x" << cols << " kind " << static_cast<int>(kind) << " trial " << trial;
          EXPECT_EQ(SolveAssignment(cost), row_to_col) << "one-shot and reused solver differ";
          ++cases;
        }
      }
    }
  }
  EXPECT_GT(cases, 1000);
}

TEST(SolveAssignment, KnownSquareOptimum) {
  Eigen::MatrixXd cost(3, 3);
  // clang-format off
  cost << 4, 1, 3,
          2, 0, 5,
          3, 2, 2;
  // clang-format on
  // The unique optimum is 1 + 2 + 2 = 5; the greedy choice (row 1 -> col 1, cost 0) loses.
  EXPECT_EQ(SolveAssignment(cost), (std::vector<int>{1, 0, 2}));
}

TEST(SolveAssignment, RectangularBothWaysAssignTheSmallerSide) {
  Eigen::MatrixXd wide(2, 4);
  // clang-format off
  wide << 9, 1, 9, 9,
          9, 9, 9, 2;
  // clang-format on
  EXPECT_EQ(SolveAssignment(wide), (std::vector<int>{1, 3}));
  const Eigen::MatrixXd tall = wide.transpose();
  EXPECT_EQ(SolveAssignment(tall), (std::vector<int>{-1, 0, -1, 1}));
}

TEST(SolveAssignment, EmptySidesGiveNoAssignment) {
  EXPECT_THAT(SolveAssignment(Eigen::MatrixXd(0, 0)), SizeIs(0));
  EXPECT_THAT(SolveAssignment(Eigen::MatrixXd(0, 5)), SizeIs(0));
  const std::vector<int> none = SolveAssignment(Eigen::MatrixXd(5, 0));
  EXPECT_THAT(none, SizeIs(5));
  EXPECT_THAT(none, Each(Eq(-1)));
}

TEST(SolveAssignment, EqualCostsGiveAnyMaximumMatching) {
  for (const auto& [rows, cols] : {std::pair{4, 4}, std::pair{3, 7}, std::pair{7, 3}}) {
    const Eigen::MatrixXd cost = Eigen::MatrixXd::Constant(rows, cols, 7.0);
    const Score score = CheckAndScore(cost, SolveAssignment(cost));
    EXPECT_EQ(score.forbidden, 0);
    EXPECT_DOUBLE_EQ(score.allowed_sum, 7.0 * std::min(rows, cols));
  }
}

TEST(SolveAssignment, ForbiddenPairsAreUsedOnlyWhenNothingElseCompletesTheMatching) {
  // Row 0 may only take column 0; row 1 prefers column 0 but can take column 1.
  Eigen::MatrixXd cost(2, 2);
  // clang-format off
  cost << 50, kForbiddenCost,
          1, 60;
  EXPECT_EQ(SolveAssignment(cost), (std::vector<int>{0, 1}));
  // Both rows may only take column 0: one gets it, the other a forbidden pair the caller drops.
  // The allowed pair kept is the cheaper one.
  cost << 50, kForbiddenCost,
          1, kForbiddenCost;
  // clang-format on
  EXPECT_EQ(SolveAssignment(cost), (std::vector<int>{1, 0}));
}

TEST(SolveAssignment, RejectsNaN) {
  Eigen::MatrixXd cost = Eigen::MatrixXd::Ones(2, 2);
  cost(1, 0) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(SolveAssignment(cost), std::invalid_argument);
  cost(1, 0) = -std::numeric_limits<double>::infinity();
  EXPECT_THROW(SolveAssignment(cost), std::invalid_argument);
}

TEST(AssignmentSolver, AcceptsAMapOverAReusedBuffer) {
  // The tracker's use: a column-major buffer viewed as a matrix without copying.
  // clang-format off
  std::vector<double> buffer = {3, 1, 2,   // column 0
                                1, 3, 3};  // column 1
  // clang-format on
  std::vector<int> row_to_col;
  AssignmentSolver solver;
  solver.Solve(Eigen::Map<const Eigen::MatrixXd>(buffer.data(), 3, 2), row_to_col);
  EXPECT_EQ(row_to_col, (std::vector<int>{1, 0, -1}));
}

// The allowed pairs of a random sparse problem, and its dense form (kForbiddenCost elsewhere).
struct SparseProblem {
  std::vector<AllowedPair> allowed;
  Eigen::MatrixXd dense;
};

SparseProblem RandomSparse(int rows, int cols, double density, std::mt19937& rng) {
  std::uniform_real_distribution<double> real(0.0, 80.0);
  std::bernoulli_distribution allow(density);
  SparseProblem problem{{}, Eigen::MatrixXd::Constant(rows, cols, kForbiddenCost)};
  for (int i = 0; i < rows; ++i) {
    for (int j = 0; j < cols; ++j) {
      if (!allow(rng)) continue;
      const double c = std::round(real(rng));  // integers: ties between groups and within them
      problem.allowed.push_back({i, j, c});
      problem.dense(i, j) = c;
    }
  }
  std::shuffle(problem.allowed.begin(), problem.allowed.end(), rng);
  return problem;
}

// Checks that every assigned pair is allowed and each column is used once; returns (number of
// pairs, their total cost).
std::pair<int, double> CheckSparse(const SparseProblem& problem,
                                   const std::vector<int>& row_to_col) {
  EXPECT_EQ(static_cast<int>(row_to_col.size()), problem.dense.rows());
  std::vector<char> taken(problem.dense.cols(), 0);
  int pairs = 0;
  double total = 0;
  for (int i = 0; i < static_cast<int>(row_to_col.size()); ++i) {
    const int j = row_to_col[i];
    if (j < 0) continue;
    EXPECT_LT(problem.dense(i, j), kForbiddenCost) << "forbidden pair " << i << "," << j;
    EXPECT_FALSE(taken[j]);
    taken[j] = 1;
    ++pairs;
    total += problem.dense(i, j);
  }
  return {pairs, total};
}

TEST(SolveSparse, MatchesBruteForceUpTo8x8) {
  std::mt19937 rng(99);
  AssignmentSolver solver;
  for (int rows = 1; rows <= 8; ++rows) {
    for (int cols = 1; cols <= 8; ++cols) {
      for (const double density : {0.1, 0.3, 0.6}) {
        const SparseProblem problem = RandomSparse(rows, cols, density, rng);
        std::vector<int> row_to_col;
        solver.SolveSparse(rows, cols, problem.allowed, row_to_col);
        const auto [pairs, total] = CheckSparse(problem, row_to_col);
        const Score want = BruteForce(problem.dense);
        EXPECT_EQ(pairs, std::min(rows, cols) - want.forbidden)
            << rows << "x" << cols << " density " << density;
        EXPECT_NEAR(total, want.allowed_sum, 1e-9) << rows << "x" << cols << " density " << density;
      }
    }
  }
}

TEST(SolveSparse, MatchesTheDenseSolverOnLargeProblems) {
  // 100 x 100 down to awkward rectangles; sparse enough to split into many groups, dense enough
  // that some groups are large.
  std::mt19937 rng(5);
  AssignmentSolver sparse_solver, dense_solver;
  for (const auto& [rows, cols] : {std::pair{100, 100}, std::pair{37, 91}, std::pair{91, 37}}) {
    for (const double density : {0.005, 0.02, 0.05}) {
      const SparseProblem problem = RandomSparse(rows, cols, density, rng);
      std::vector<int> sparse_answer, dense_answer;
      sparse_solver.SolveSparse(rows, cols, problem.allowed, sparse_answer);
      dense_solver.Solve(problem.dense, dense_answer);
      for (int i = 0; i < rows; ++i) {
        if (dense_answer[i] >= 0 && problem.dense(i, dense_answer[i]) >= kForbiddenCost) {
          dense_answer[i] = -1;  // the caller's drop
        }
      }
      const auto [sparse_pairs, sparse_total] = CheckSparse(problem, sparse_answer);
      const auto [dense_pairs, dense_total] = CheckSparse(problem, dense_answer);
      EXPECT_EQ(sparse_pairs, dense_pairs) << rows << "x" << cols << " density " << density;
      EXPECT_NEAR(sparse_total, dense_total, 1e-6) << rows << "x" << cols << " density " << density;
    }
  }
}

TEST(SolveSparse, EmptyAndInvalidInput) {
  AssignmentSolver solver;
  std::vector<int> row_to_col;
  solver.SolveSparse(3, 4, {}, row_to_col);
  EXPECT_EQ(row_to_col, (std::vector<int>{-1, -1, -1}));
  solver.SolveSparse(0, 4, {}, row_to_col);
  EXPECT_THAT(row_to_col, SizeIs(0));
  EXPECT_THROW(solver.SolveSparse(2, 2, {{0, 2, 1.0}}, row_to_col), std::invalid_argument);
  EXPECT_THROW(
      solver.SolveSparse(2, 2, {{0, 1, std::numeric_limits<double>::quiet_NaN()}}, row_to_col),
      std::invalid_argument);
}

}  // namespace
}  // namespace stevi::tracking
