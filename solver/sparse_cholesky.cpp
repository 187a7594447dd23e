#include "solver/sparse_cholesky.h"

#include <cholmod.h>

#include <cstring>

namespace flank {

struct SparseCholesky::Impl {
  cholmod_common common;
  cholmod_sparse* A = nullptr;
  cholmod_factor* L = nullptr;
  int n = 0;
  std::string message;

  Impl() {
    cholmod_start(&common);
    // The normal matrices are small and banded: simplicial LDLᵀ avoids BLAS threads inside
    // concurrent TBB tasks and is faster at this size.
    common.supernodal = CHOLMOD_SIMPLICIAL;
    // In the given order: a band with the profile's few columns last fills in nothing that an
    // ordering would save, and the factorisation then reads the upper triangle as it is given.
    // A fill-reducing permutation made CHOLMOD transpose the matrix twice per factorisation, a
    // quarter of the factorisation's time.
    common.nmethods = 1;
    common.method[0].ordering = CHOLMOD_NATURAL;
    common.postorder = 0;
    common.print = 0;
    common.error_handler = nullptr;
  }
  ~Impl() {
    if (L) cholmod_free_factor(&L, &common);
    if (A) cholmod_free_sparse(&A, &common);
    cholmod_finish(&common);
  }
};

SparseCholesky::SparseCholesky() : impl_(std::make_unique<Impl>()) {}
SparseCholesky::~SparseCholesky() = default;

SparseCholesky::Status SparseCholesky::analyze(int n, std::vector<int> col_ptr,
                                               std::vector<int> row_idx) {
  Impl& m = *impl_;
  if (m.L) cholmod_free_factor(&m.L, &m.common);
  if (m.A) cholmod_free_sparse(&m.A, &m.common);
  m.n = n;
  const std::size_t nnz = row_idx.size();
  m.A = cholmod_allocate_sparse(n, n, nnz, /*sorted=*/1, /*packed=*/1, /*stype=*/1, CHOLMOD_REAL,
                                &m.common);
  if (!m.A) {
    m.message = "CHOLMOD could not allocate the normal matrix";
    return Status::failed;
  }
  std::memcpy(m.A->p, col_ptr.data(), sizeof(int) * col_ptr.size());
  std::memcpy(m.A->i, row_idx.data(), sizeof(int) * nnz);
  std::memset(m.A->x, 0, sizeof(double) * nnz);
  m.L = cholmod_analyze(m.A, &m.common);
  if (!m.L || m.common.status < CHOLMOD_OK) {
    m.message = "CHOLMOD symbolic analysis failed";
    return Status::failed;
  }
  return Status::ok;
}

SparseCholesky::Status SparseCholesky::factorize(const std::vector<double>& values) {
  Impl& m = *impl_;
  if (!m.A || !m.L) return Status::failed;
  std::memcpy(m.A->x, values.data(), sizeof(double) * values.size());
  cholmod_factorize(m.A, m.L, &m.common);
  if (m.common.status == CHOLMOD_NOT_POSDEF || m.L->minor < static_cast<std::size_t>(m.n)) {
    m.message = "normal matrix is not positive definite";
    return Status::not_positive_definite;
  }
  if (m.common.status < CHOLMOD_OK) {
    m.message = "CHOLMOD numeric factorisation failed";
    return Status::failed;
  }
  return Status::ok;
}

SparseCholesky::Status SparseCholesky::solve(const VecX& rhs, VecX* x) {
  Impl& m = *impl_;
  cholmod_dense* b = cholmod_allocate_dense(m.n, 1, m.n, CHOLMOD_REAL, &m.common);
  if (!b) return Status::failed;
  std::memcpy(b->x, rhs.data(), sizeof(double) * m.n);
  cholmod_dense* sol = cholmod_solve(CHOLMOD_A, m.L, b, &m.common);
  cholmod_free_dense(&b, &m.common);
  if (!sol) {
    m.message = "CHOLMOD solve failed";
    return Status::failed;
  }
  x->resize(m.n);
  std::memcpy(x->data(), sol->x, sizeof(double) * m.n);
  cholmod_free_dense(&sol, &m.common);
  return x->allFinite() ? Status::ok : Status::failed;
}

std::string SparseCholesky::message() const { return impl_->message; }

}  // namespace flank
