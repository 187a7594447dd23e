// Sparse Cholesky of a symmetric positive definite matrix with a fixed pattern: symbolic
// analysis once, numeric factorisation per Gauss–Newton iteration (STYLE 7). CHOLMOD stays
// behind Impl; each instance owns its own workspace, so one per concurrent fit.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "kernels/types.h"

namespace flank {

class SparseCholesky {
 public:
  enum class Status { ok, not_positive_definite, failed };

  SparseCholesky();
  ~SparseCholesky();
  SparseCholesky(const SparseCholesky&) = delete;
  SparseCholesky& operator=(const SparseCholesky&) = delete;

  // Upper triangle in compressed columns: col_ptr has n+1 entries, row_idx the sorted rows
  // (≤ column) of every column, each column's rows without gaps up to the diagonal (an
  // envelope: its factor fills in nothing outside it, so the given order is kept).
  Status analyze(int n, std::vector<int> col_ptr, std::vector<int> row_idx);
  // Values in the pattern's order.
  Status factorize(const std::vector<double>& values);
  // Solves A x = rhs with the last factorisation.
  Status solve(const VecX& rhs, VecX* x);
  std::string message() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace flank
