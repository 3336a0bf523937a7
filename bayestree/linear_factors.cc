#include "arbor_slam/bayestree/linear_factors.h"

#include <algorithm>
#include <exception>

#include "arbor_slam/core/factor_error.h"

namespace arbor::bayestree {

template <class G>
int LinearizedFactors<G>::add(const Factor<G>& e) {
  const int f = numFactors();
  factors.push_back(e);
  lin.emplace_back();
  stamp.push_back(-1);
  attached.push_back(0);
  if (e.inlierWeight() > 0) attach(f);
  return f;
}

template <class G>
void LinearizedFactors<G>::attach(int f) {
  if (attached[f]) return;
  attached[f] = 1;
  const Factor<G>& e = factors[f];
  for (int k = 0; k < e.arity(); ++k) var_factors[e.key(k)].push_back(f);
}

// attach appends: a re-admitted factor is summed last in its keys' assemblies, as a factor
// added anew would be.
template <class G>
void LinearizedFactors<G>::detach(int f) {
  if (!attached[f]) return;
  attached[f] = 0;
  const Factor<G>& e = factors[f];
  for (int k = 0; k < e.arity(); ++k) {
    std::vector<int>& list = var_factors[e.key(k)];
    list.erase(std::find(list.begin(), list.end(), f));
  }
}

template <class G>
void LinearizedFactors<G>::linearize(int f, const std::vector<G>& theta) {
  linearize(f, theta, &lin[f]);
}

template <class G>
void LinearizedFactors<G>::linearize(int f, const std::vector<G>& theta, LinearFactor* out) const {
  typename Factor<G>::Linearization A;
  factors[f].linearizeWeighted(theta, &A);
  LinearFactor& L = *out;
  const int n = factors[f].arity();
  for (int k = 0; k < n; ++k) {
    for (int l = 0; l <= k; ++l) L.H[L.block(k, l)].noalias() = A.A[k].transpose() * A.A[l];
    L.g[k].noalias() = -A.A[k].transpose() * A.r;
  }
}

template <class G>
void LinearizedFactors<G>::linearizeAll(const std::vector<int>& fs, const std::vector<G>& theta,
                                        UpdateThreads* threads,
                                        const std::function<void()>& alongside) {
  constexpr int kChunk = 128;
  constexpr int kMinSharedChunks = 4;  // fewer factors are linearised in well under 0.1 ms
  const int n = static_cast<int>(fs.size());
  const int chunks = (n + kChunk - 1) / kChunk;
  std::vector<int>& items = threads->ready;
  items.clear();
  for (int k = 0; k < chunks; ++k) items.push_back(k);
  if (alongside) items.push_back(chunks);  // taken first (the pool is a stack)
  threads->workers.run(
      items,
      [&](int, int k) {
        if (k == chunks) {
          alongside();
        } else {
          for (int i = k * kChunk; i < std::min(n, (k + 1) * kChunk); ++i) linearize(fs[i], theta);
        }
        return -1;
      },
      /*share=*/chunks >= kMinSharedChunks);
}

template <class G>
void LinearizedFactors<G>::linearizeAllOrNone(const std::vector<int>& fs,
                                              const std::vector<G>& theta, UpdateThreads* threads,
                                              std::vector<LinearFactor>* staged) {
  constexpr int kChunk = 8;  // factors of your own: each call may be long (a Python function)
  const int n = static_cast<int>(fs.size());
  if (n == 0) return;
  staged->resize(fs.size());
  const int chunks = (n + kChunk - 1) / kChunk;
  // The first failure in fs order (whichever thread met it), so the message does not depend on
  // the scheduling.
  std::vector<std::exception_ptr> errors(static_cast<size_t>(chunks));
  std::vector<int> failed(static_cast<size_t>(chunks), -1);
  std::vector<int>& items = threads->ready;
  items.clear();
  for (int k = 0; k < chunks; ++k) items.push_back(k);
  threads->workers.run(
      items,
      [&](int, int k) {
        for (int i = k * kChunk; i < std::min(n, (k + 1) * kChunk); ++i) {
          try {
            linearize(fs[i], theta, &(*staged)[static_cast<size_t>(i)]);
          } catch (...) {
            errors[static_cast<size_t>(k)] = std::current_exception();
            failed[static_cast<size_t>(k)] = i;
            break;
          }
        }
        return -1;
      },
      /*share=*/chunks >= 2);
  for (int k = 0; k < chunks; ++k) {
    if (!errors[static_cast<size_t>(k)]) continue;
    const int f = fs[static_cast<size_t>(failed[static_cast<size_t>(k)])];
    try {
      std::rethrow_exception(errors[static_cast<size_t>(k)]);
    } catch (...) {
      throwFactorError(factorText(factors[f], f, theta), f);
    }
  }
  for (int i = 0; i < n; ++i) lin[fs[i]] = (*staged)[static_cast<size_t>(i)];
}

template class LinearizedFactors<SE2>;
template class LinearizedFactors<SE3>;

}  // namespace arbor::bayestree
