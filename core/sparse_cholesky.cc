#include "arbor_slam/core/sparse_cholesky.h"

#include <cholmod.h>

#include <limits>
#include <numeric>
#include <stdexcept>
#include <utility>

#include "arbor_slam/core/blas_threads.h"
#include "arbor_slam/core/serial_openmp.h"

namespace arbor {
namespace {

// A cholmod_sparse header over our arrays (no copy; never freed by CHOLMOD).
cholmod_sparse view(const SymmetricPattern& p, const double* values) {
  cholmod_sparse a{};
  a.nrow = a.ncol = static_cast<size_t>(p.n);
  a.nzmax = static_cast<size_t>(p.col_ptr.back());
  a.p = const_cast<int*>(p.col_ptr.data());
  a.i = const_cast<int*>(p.row_idx.data());
  a.nz = nullptr;
  a.x = const_cast<double*>(values);
  a.z = nullptr;
  a.stype = 1;  // upper triangle stored
  a.itype = CHOLMOD_INT;
  a.xtype = values ? CHOLMOD_REAL : CHOLMOD_PATTERN;
  a.dtype = CHOLMOD_DOUBLE;
  a.sorted = 1;
  a.packed = 1;
  return a;
}

void checkPattern(const SymmetricPattern& p, const char* where) {
  if (p.n < 0 || static_cast<int>(p.col_ptr.size()) != p.n + 1 || p.col_ptr.front() != 0 ||
      static_cast<int>(p.row_idx.size()) != p.col_ptr.back())
    throw std::invalid_argument(
        std::string(where) + ": inconsistent sparsity pattern (n = " + std::to_string(p.n) + ")");
}

// Owns a cholmod_common set up quietly (no printing) for LLᵀ.
struct Common {
  cholmod_common c;
  Common() {
    cholmod_start(&c);
    c.print = 0;
    c.final_ll = 1;
    c.quick_return_if_not_posdef = 1;
  }
  ~Common() { cholmod_finish(&c); }
  Common(const Common&) = delete;
  Common& operator=(const Common&) = delete;
};

}  // namespace

std::vector<int> fillReducingOrdering(const SymmetricPattern& pattern,
                                      double nested_dissection_flops, double* flops) {
  checkPattern(pattern, "fillReducingOrdering");
  std::vector<int> order(pattern.n);
  std::iota(order.begin(), order.end(), 0);
  if (flops) *flops = 0.0;
  if (pattern.n == 0) return order;
  double best_flops = std::numeric_limits<double>::infinity();
  for (const int method : {CHOLMOD_AMD, CHOLMOD_METIS, CHOLMOD_NESDIS}) {
    if (method != CHOLMOD_AMD && best_flops <= nested_dissection_flops) break;
    Common common;
    common.c.nmethods = 1;
    common.c.method[0].ordering = method;
    cholmod_sparse a = view(pattern, nullptr);
    cholmod_factor* l = cholmod_analyze(&a, &common.c);
    if (!l) continue;  // e.g. METIS not compiled in: the others remain
    if (common.c.fl < best_flops) {
      best_flops = common.c.fl;
      const int* perm = static_cast<const int*>(l->Perm);
      order.assign(perm, perm + pattern.n);
    }
    cholmod_free_factor(&l, &common.c);
  }
  if (flops) *flops = best_flops;
  return order;
}

struct SparseCholesky::Cholmod {
  Common common;
  cholmod_factor* factor = nullptr;
  cholmod_dense* x = nullptr;  // solve output and workspaces, reused
  cholmod_dense* y = nullptr;
  cholmod_dense* e = nullptr;
  ~Cholmod() {
    cholmod_free_dense(&x, &common.c);
    cholmod_free_dense(&y, &common.c);
    cholmod_free_dense(&e, &common.c);
    cholmod_free_factor(&factor, &common.c);
  }
};

SparseCholesky::SparseCholesky(SymmetricPattern pattern)
    : pattern_(std::move(pattern)), cholmod_(std::make_unique<Cholmod>()) {
  useOneBlasThread();  // CHOLMOD's supernodal factorisation calls the BLAS
  checkPattern(pattern_, "SparseCholesky");
  cholmod_common& c = cholmod_->common.c;
  c.nmethods = 1;
  c.method[0].ordering = CHOLMOD_NATURAL;
  c.postorder = 0;
  cholmod_sparse a = view(pattern_, nullptr);
  cholmod_->factor = cholmod_analyze(&a, &c);
  if (!cholmod_->factor)
    throw std::runtime_error("SparseCholesky: CHOLMOD analysis failed (status " +
                             std::to_string(c.status) + ")");
}

SparseCholesky::~SparseCholesky() = default;

bool SparseCholesky::factorize(const double* values) {
  cholmod_common& c = cholmod_->common.c;
  cholmod_sparse a = view(pattern_, values);
  factorized_ = false;
  failed_column_ = -1;
  const SerialOpenMP serial;
  const int ok = cholmod_factorize(&a, cholmod_->factor, &c);
  if (!ok || c.status != CHOLMOD_OK || cholmod_->factor->minor < cholmod_->factor->n) {
    failed_column_ = static_cast<int>(cholmod_->factor->minor);
    return false;
  }
  factorized_ = true;
  return true;
}

void SparseCholesky::solve(const Eigen::VectorXd& b, Eigen::VectorXd* x) {
  if (!factorized_) throw std::logic_error("SparseCholesky::solve: no successful factorisation");
  if (b.size() != pattern_.n)
    throw std::invalid_argument("SparseCholesky::solve: right-hand side of size " +
                                std::to_string(b.size()) + ", expected " +
                                std::to_string(pattern_.n));
  cholmod_common& c = cholmod_->common.c;
  cholmod_dense rhs{};
  rhs.nrow = rhs.d = static_cast<size_t>(pattern_.n);
  rhs.ncol = 1;
  rhs.nzmax = rhs.nrow;
  rhs.x = const_cast<double*>(b.data());
  rhs.xtype = CHOLMOD_REAL;
  rhs.dtype = CHOLMOD_DOUBLE;
  if (!cholmod_solve2(CHOLMOD_A, cholmod_->factor, &rhs, nullptr, &cholmod_->x, nullptr,
                      &cholmod_->y, &cholmod_->e, &c))
    throw std::runtime_error("SparseCholesky::solve: CHOLMOD solve failed (status " +
                             std::to_string(c.status) + ")");
  *x = Eigen::Map<const Eigen::VectorXd>(static_cast<const double*>(cholmod_->x->x), pattern_.n);
}

double SparseCholesky::factorNonzeros() const { return cholmod_->common.c.lnz; }
double SparseCholesky::factorFlops() const { return cholmod_->common.c.fl; }

}  // namespace arbor
