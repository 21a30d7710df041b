#include "core/tracking/hungarian.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>

namespace stevi::tracking {

void AssignmentSolver::Solve(const Eigen::Ref<const Eigen::MatrixXd>& cost,
                             std::vector<int>& row_to_col) {
  const int rows = static_cast<int>(cost.rows());
  const int cols = static_cast<int>(cost.cols());
  row_to_col.assign(rows, -1);
  if (rows == 0 || cols == 0) return;

  // The algorithm augments once per row and needs n <= m: solve the transpose when there are more
  // rows than columns.
  const bool transposed = rows > cols;
  const int n = transposed ? cols : rows;
  const int m = transposed ? rows : cols;
  LoadProblem(cost, transposed, n, m);

  // Index 0 is a virtual column (and row) that roots each augmenting path.
  u_.assign(n + 1, 0.0);
  v_.assign(m + 1, 0.0);
  row_of_col_.assign(m + 1, 0);
  way_.assign(m + 1, 0);
  min_slack_.resize(m + 1);
  used_.resize(m + 1);
  for (int i = 1; i <= n; ++i) Augment(i, m);

  for (int j = 1; j <= m; ++j) {
    const int i = row_of_col_[j];
    if (i == 0) continue;
    if (transposed) {
      row_to_col[j - 1] = i - 1;
    } else {
      row_to_col[i - 1] = j - 1;
    }
  }
}

void AssignmentSolver::LoadProblem(const Eigen::Ref<const Eigen::MatrixXd>& cost, bool transposed,
                                   int n, int m) {
  // Row-major, so that the inner loop over columns is contiguous.
  a_.resize(static_cast<size_t>(n) * m);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < m; ++j) {
      double c = transposed ? cost(j, i) : cost(i, j);
      if (c == std::numeric_limits<double>::infinity()) c = kForbiddenCost;
      if (!std::isfinite(c)) {
        throw std::invalid_argument("SolveAssignment: costs must be finite or +infinity");
      }
      a_[static_cast<size_t>(i) * m + j] = c;
    }
  }
}

void AssignmentSolver::Augment(int i, int m) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  // Grow a shortest-path tree (reduced costs a - u - v >= 0 are the edge lengths) from row i
  // until it reaches a free column, then flip the path. Each step adds the column of least slack
  // and shifts the potentials by that slack, which keeps every reduced cost non-negative and
  // every tree edge tight.
  row_of_col_[0] = i;
  int j0 = 0;
  std::fill(min_slack_.begin(), min_slack_.end(), kInf);
  std::fill(used_.begin(), used_.end(), char{0});
  do {
    used_[j0] = 1;
    const int i0 = row_of_col_[j0];
    const double* a_row = &a_[static_cast<size_t>(i0 - 1) * m];
    const double u_i0 = u_[i0];
    double delta = kInf;
    int j1 = 0;
    for (int j = 1; j <= m; ++j) {
      if (used_[j]) continue;
      const double reduced = a_row[j - 1] - u_i0 - v_[j];
      if (reduced < min_slack_[j]) {
        min_slack_[j] = reduced;
        way_[j] = j0;
      }
      if (min_slack_[j] < delta) {
        delta = min_slack_[j];
        j1 = j;
      }
    }
    // n <= m, so an unused column always exists and j1 is set.
    for (int j = 0; j <= m; ++j) {
      if (used_[j]) {
        u_[row_of_col_[j]] += delta;
        v_[j] -= delta;
      } else {
        min_slack_[j] -= delta;
      }
    }
    j0 = j1;
  } while (row_of_col_[j0] != 0);
  // Augment: walk the path back to the root, shifting each matched row one column along.
  do {
    const int j1 = way_[j0];
    row_of_col_[j0] = row_of_col_[j1];
    j0 = j1;
  } while (j0 != 0);
}

int AssignmentSolver::Find(int node) {
  while (parent_[node] != node) {
    parent_[node] = parent_[parent_[node]];  // path halving
    node = parent_[node];
  }
  return node;
}

void AssignmentSolver::SolveSparse(int rows, int cols, const std::vector<AllowedPair>& allowed,
                                   std::vector<int>& row_to_col) {
  row_to_col.assign(std::max(rows, 0), -1);
  if (rows <= 0 || cols <= 0 || allowed.empty()) return;
  const int nodes = rows + cols;
  parent_.resize(nodes);
  std::iota(parent_.begin(), parent_.end(), 0);
  for (const AllowedPair& p : allowed) {
    if (p.row < 0 || p.row >= rows || p.col < 0 || p.col >= cols || !std::isfinite(p.cost)) {
      throw std::invalid_argument("SolveSparse: a pair is out of range or its cost is not finite");
    }
    const int a = Find(p.row), b = Find(rows + p.col);
    if (a != b) parent_[a] = b;
  }

  // Number the groups; rows and columns in no pair belong to none and stay unassigned.
  group_of_root_.assign(nodes, -1);
  group_of_.assign(nodes, -1);
  int groups = 0;
  for (const AllowedPair& p : allowed) {
    for (const int node : {p.row, rows + p.col}) {
      if (group_of_[node] >= 0) continue;
      int& root_group = group_of_root_[Find(node)];
      if (root_group < 0) root_group = groups++;
      group_of_[node] = root_group;
    }
  }
  group_rows_.assign(groups, 0);
  group_cols_.assign(groups, 0);
  local_of_.assign(nodes, -1);
  for (int node = 0; node < nodes; ++node) {
    const int g = group_of_[node];
    if (g >= 0) local_of_[node] = node < rows ? group_rows_[g]++ : group_cols_[g]++;
  }
  // Members of each group, rows first then columns, each in its local order.
  member_start_.assign(groups + 1, 0);
  for (int g = 0; g < groups; ++g) {
    member_start_[g + 1] = member_start_[g] + group_rows_[g] + group_cols_[g];
  }
  members_.resize(member_start_[groups]);
  for (int node = 0; node < nodes; ++node) {
    const int g = group_of_[node];
    if (g < 0) continue;
    const int offset = node < rows ? local_of_[node] : group_rows_[g] + local_of_[node];
    members_[member_start_[g] + offset] = node;
  }
  // Pairs of each group (counting sort).
  pair_start_.assign(groups + 1, 0);
  for (const AllowedPair& p : allowed) ++pair_start_[group_of_[p.row] + 1];
  for (int g = 0; g < groups; ++g) pair_start_[g + 1] += pair_start_[g];
  cursor_.assign(pair_start_.begin(), pair_start_.end() - 1);
  pair_order_.resize(allowed.size());
  for (int i = 0; i < static_cast<int>(allowed.size()); ++i) {
    pair_order_[cursor_[group_of_[allowed[i].row]]++] = i;
  }

  for (int g = 0; g < groups; ++g) {
    const int r = group_rows_[g], c = group_cols_[g];
    const int* member = &members_[member_start_[g]];
    if (r == 1 && c == 1) {  // the common case: one track, one detection
      row_to_col[member[0]] = member[1] - rows;
      continue;
    }
    group_cost_.assign(static_cast<size_t>(r) * c, kForbiddenCost);
    for (int i = pair_start_[g]; i < pair_start_[g + 1]; ++i) {
      const AllowedPair& p = allowed[pair_order_[i]];
      group_cost_[static_cast<size_t>(local_of_[rows + p.col]) * r + local_of_[p.row]] = p.cost;
    }
    Solve(Eigen::Map<const Eigen::MatrixXd>(group_cost_.data(), r, c), group_assignment_);
    for (int i = 0; i < r; ++i) {
      const int j = group_assignment_[i];
      if (j < 0 || group_cost_[static_cast<size_t>(j) * r + i] >= kForbiddenCost) continue;
      row_to_col[member[i]] = member[r + j] - rows;
    }
  }
}

std::vector<int> SolveAssignment(const Eigen::Ref<const Eigen::MatrixXd>& cost) {
  AssignmentSolver solver;
  std::vector<int> row_to_col;
  solver.Solve(cost, row_to_col);
  return row_to_col;
}

}  // namespace stevi::tracking
