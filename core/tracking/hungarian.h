// The rectangular assignment problem (Kuhn-Munkres), used to pair tracks with detections.
#pragma once

#include <vector>

#include <Eigen/Core>

namespace stevi::tracking {

// The cost of a pair that must not be matched (outside a gate). The solver itself treats it as an
// ordinary cost. Gating is the caller's job: it gives every forbidden pair this cost and drops
// every forbidden pair from the solution. Because this cost exceeds the sum of the allowed costs in
// any matching (min(rows, cols) times the largest allowed cost; the tracker's allowed costs are
// pixel distances below its distance gate), the solution first uses as few forbidden pairs as
// possible, which keeps as many allowed pairs as any matching can, and then minimises their total
// cost.
inline constexpr double kForbiddenCost = 1e9;

// One pair that may be matched, in the sparse form of the problem.
struct AllowedPair {
  int row = 0;
  int col = 0;
  double cost = 0;  // finite and below kForbiddenCost
};

// Reuses its buffers from call to call, so that solving every frame does not allocate once the
// sizes have been seen. Thread-compatible: one solver per thread.
class AssignmentSolver {
 public:
  // Minimum-cost maximum-cardinality assignment for `cost` (rows x cols, either may be larger,
  // either may be 0). On return `row_to_col` has one entry per row: the assigned column, or -1.
  // Exactly min(rows, cols) rows are assigned, with the smallest total cost among all assignments
  // of that size. Costs are finite; +infinity is read as kForbiddenCost. NaN or -infinity is a
  // programming error (std::invalid_argument).
  // Kuhn-Munkres in its shortest-augmenting-path form with dual potentials: one augmentation per
  // row of the smaller side, O(n^2 m) time with n = min(rows, cols), m = max(rows, cols).
  void Solve(const Eigen::Ref<const Eigen::MatrixXd>& cost, std::vector<int>& row_to_col);

  // The gated problem in sparse form: `allowed` lists the pairs that may be matched (each at most
  // once), every other pair is forbidden. The answer is Solve() on the dense matrix with
  // kForbiddenCost everywhere else, minus its forbidden pairs: as many allowed pairs as any
  // matching can keep, at the least total cost; -1 for every other row.
  // Rows and columns linked by no allowed pair never interact, so the problem splits into the
  // connected groups of the allowed pairs, each solved densely on its own. A scene of separate
  // obstacles (one track and one detection per group) then costs O(rows + cols + pairs) instead
  // of O(n^2 m).
  void SolveSparse(int rows, int cols, const std::vector<AllowedPair>& allowed,
                   std::vector<int>& row_to_col);

 private:
  // Solve's steps: the cost matrix (transposed when it has more rows than columns) into a_, n x m
  // with n <= m, forbidden pairs at kForbiddenCost (std::invalid_argument for a cost that is NaN or
  // -infinity); then one shortest augmenting path from row i (1-based) over the m columns, which
  // updates the potentials and the matching.
  void LoadProblem(const Eigen::Ref<const Eigen::MatrixXd>& cost, bool transposed, int n, int m);
  void Augment(int i, int m);
  int Find(int node);

  // SolveSparse, over nodes (the rows, then the columns): union-find parents; the group of each
  // root and of each node in a pair; each node's index among its group's rows or columns. Per
  // group: its numbers of rows and columns, its members (rows then columns) and its pairs.
  std::vector<int> parent_, group_of_root_, group_of_, local_of_;
  std::vector<int> group_rows_, group_cols_, member_start_, members_, pair_start_, pair_order_;
  std::vector<int> cursor_;
  std::vector<double> group_cost_;
  std::vector<int> group_assignment_;

  // The problem with n <= m, row-major, 1-based as in the classic formulation: a_[(i-1) * m + j-1].
  std::vector<double> a_;
  std::vector<double> u_, v_, min_slack_;  // row and column potentials; slack of each column
  std::vector<int> row_of_col_, way_;      // matched row of each column (0: none); path links
  std::vector<char> used_;
};

// One-shot form of AssignmentSolver::Solve.
std::vector<int> SolveAssignment(const Eigen::Ref<const Eigen::MatrixXd>& cost);

}  // namespace stevi::tracking
