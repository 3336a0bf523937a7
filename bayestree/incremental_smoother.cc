#include "bayestree/incremental_smoother.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <deque>
#include <functional>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <variant>

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "bayestree/clique.h"
#include "bayestree/dense_kernels.h"
#include "bayestree/dogleg_step.h"
#include "bayestree/elimination_plan.h"
#include "bayestree/work_lanes.h"
#include "core/information.h"

namespace arbor {
namespace {

using bayestree::DoubleBuffer;
using bayestree::partialCholesky;

using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

bool isFinitePose(const SE2& x) {
  return std::isfinite(x.x()) && std::isfinite(x.y()) && std::isfinite(x.cos()) &&
         std::isfinite(x.sin());
}
bool isFinitePose(const SE3& x) {
  return x.translation().allFinite() && x.quaternion().coeffs().allFinite();
}

void accumulate(UpdateStats* total, const UpdateStats& s) {
  total->new_factors += s.new_factors;
  total->new_variables += s.new_variables;
  total->cliques_reeliminated += s.cliques_reeliminated;
  total->variables_reeliminated += s.variables_reeliminated;
  total->variables_relinearized += s.variables_relinearized;
  total->indeterminate_cliques += s.indeterminate_cliques;
  total->cliques_solved += s.cliques_solved;
  total->cliques_updated += s.cliques_updated;
  total->cliques_on_helpers += s.cliques_on_helpers;
}

}  // namespace

template <class G>
struct IncrementalSmoother<G>::Impl {
  static constexpr int D = G::kDoF;
  static constexpr int kTrans = G::kDim;  // the first kDim tangent entries are translational
  using Mat = Eigen::Matrix<double, D, D>;
  using Vec = Tangent;

  // One whitened factor ‖Σ_k A_k τ_k + r‖² over its keys in Hessian form: τᵀHτ − 2gᵀτ + rᵀr,
  // H_kl = A_kᵀA_l, g_k = −A_kᵀr; H is kept as its lower triangle of blocks, H(k, l) for k ≥ l
  // at block(k, l).
  static constexpr int kMaxKeys = Factor<G>::kMaxKeys;
  struct LinearFactor {
    std::array<Mat, kMaxKeys*(kMaxKeys + 1) / 2> H;
    std::array<Vec, kMaxKeys> g;
    static int block(int k, int l) { return k * (k + 1) / 2 + l; }
    // H(k, l) for any k, l.
    Mat at(int k, int l) const { return k >= l ? H[block(k, l)] : H[block(l, k)].transpose(); }
  };
  using Clique = bayestree::Clique<D>;

  SmootherOptions opt;
  std::vector<G> theta;
  std::vector<char> fixed;
  std::vector<Vec> delta;         // the step applied: Gauss–Newton or dogleg
  std::vector<Vec> delta_newton;  // the Gauss–Newton solution of the Bayes tree
  std::vector<Vec> delta_seen;    // Δ_newton as last propagated to the cliques below (Alg. 3)
  std::vector<int> clique_of;     // pose → clique where it is frontal (−1: fixed / new)
  std::vector<std::vector<int>> var_factors;
  std::vector<Factor<G>> edges;  // every factor added by update(), in order
  std::vector<LinearFactor> lin;
  std::vector<int> factor_stamp;
  std::vector<Factor<G>> queued;
  std::vector<int> to_touch;        // variables whose cliques the next update re-eliminates
  std::vector<int> to_relinearize;  // factors the next update relinearises (transformPoses)
  std::vector<int> new_vars;
  std::vector<Clique> cliques;
  std::vector<int> free_cliques;
  std::vector<int> roots;
  int num_cliques = 0;
  int update_count = 0;
  int path_stamp = 0;
  int stamp = 0;
  double dogleg_radius = 1.0;
  // Scratch indexed by pose, always restored to −1 / 0 after use (no O(n) clearing).
  std::vector<int> slot;  // lane 0's (and the single-threaded steps')
  std::vector<char> mark, changed;
  // What one thread uses while it eliminates or back-substitutes cliques (reused: no
  // per-clique malloc).
  struct Lane {
    std::vector<int> slot;  // lanes 1..: their own slot (lane 0 uses Impl::slot)
    DoubleBuffer h;         // the clique's assembled Hessian
    std::vector<double> diag, x;
    std::vector<int> child_slots, changed_list;
    std::deque<int> pending;                            // cliques this thread is to back-substitute
    int solved = 0, eliminated = 0, indeterminate = 0;  // cliques, in the current walk
  };
  // The threads of an update (SmootherOptions::threads): lane 0 is the caller's. A copy of the
  // smoother gets threads of its own.
  struct Threads {
    explicit Threads(int n) : lanes(n), workers(n) {}
    Threads(const Threads& o) : lanes(o.lanes), workers(o.workers.lanes()) {}
    Threads& operator=(const Threads&) = delete;
    std::vector<Lane> lanes;
    bayestree::WorkLanes workers;
  };
  Threads threads;
  DoubleBuffer extend_buf;
  DoubleBuffer w_buf, w_parent_buf;  // a fold-in's W of this clique and of its parent
  std::vector<int> stack_scratch, ready_scratch;
  std::vector<int> s_path;       // cliques whose separator a fold-in extends
  std::vector<int> s_linearize;  // factors to (re-)linearise in this update
  std::vector<double> s_chain_flops;
  std::vector<int> s_touched, s_relin, s_marked, s_removed, s_top, s_orphans, s_group, s_ids;
  bayestree::RowList s_rows;
  std::vector<int> s_by_need, s_by_capacity;
  std::vector<DoubleBuffer> s_buffers;

  static int threadCount(int requested) {
    if (requested < 0)
      throw std::invalid_argument("IncrementalSmoother: bad option threads = " +
                                  std::to_string(requested));
    if (requested > 0) return requested;
    return static_cast<int>(std::clamp(std::thread::hardware_concurrency(), 1u, 4u));
  }

  explicit Impl(const SmootherOptions& o)
      : opt(o), dogleg_radius(o.dogleg_initial_radius), threads(threadCount(o.threads)) {
    auto bad = [](const std::string& what, double v, const char* must) {
      std::ostringstream msg;
      msg << "IncrementalSmoother: bad option " << what << " = " << v << " (must be " << must
          << ")";
      throw std::invalid_argument(msg.str());
    };
    if (!(o.relinearize_threshold_translation >= 0))
      bad("relinearize_threshold_translation", o.relinearize_threshold_translation, "≥ 0");
    if (!(o.relinearize_threshold_rotation >= 0))
      bad("relinearize_threshold_rotation", o.relinearize_threshold_rotation, "≥ 0");
    if (o.relinearize_skip < 1) bad("relinearize_skip", o.relinearize_skip, "≥ 1");
    if (o.nested_dissection_min < -1) bad("nested_dissection_min", o.nested_dissection_min, "≥ −1");
    if (!(o.wildfire_threshold >= 0)) bad("wildfire_threshold", o.wildfire_threshold, "≥ 0");
    if (!(o.dogleg_initial_radius > 0))
      bad("dogleg_initial_radius", o.dogleg_initial_radius, "> 0");
    if (!(o.dogleg_min_radius > 0)) bad("dogleg_min_radius", o.dogleg_min_radius, "> 0");
    if (!(o.finalize_relative_tolerance >= 0))
      bad("finalize_relative_tolerance", o.finalize_relative_tolerance, "≥ 0");
    if (o.finalize_max_iterations < 1)
      bad("finalize_max_iterations", o.finalize_max_iterations, "≥ 1");
  }

  int numPoses() const { return static_cast<int>(theta.size()); }

  void releaseFixedPose(int v) {
    if (v < 0 || v >= numPoses() || !fixed[v])
      throw std::invalid_argument("IncrementalSmoother::releaseFixedPose: " + std::to_string(v) +
                                  " is not a fixed pose");
    fixed[v] = 0;
    new_vars.push_back(v);
    // Its factors were unary terms on their other keys, assembled in those keys' cliques: these
    // are re-eliminated with v as a variable.
    for (int f : var_factors[v])
      for (int k = 0; k < edges[f].arity(); ++k)
        if (edges[f].key(k) != v && !fixed[edges[f].key(k)]) to_touch.push_back(edges[f].key(k));
  }

  void transformPoses(const std::vector<int>& poses, const G& T) {
    if (!isFinitePose(T))
      throw std::invalid_argument("IncrementalSmoother::transformPoses: transform not finite");
    for (int v : poses)
      if (v < 0 || v >= numPoses())
        throw std::invalid_argument("IncrementalSmoother::transformPoses: index " +
                                    std::to_string(v) + " out of range");
    for (int v : poses) mark[v] = 1;
    for (int v : poses) {
      theta[v] = T.compose(theta[v]);
      theta[v].normalize();
      for (int f : var_factors[v]) {
        const Factor<G>& e = edges[f];
        if (e.kind() == FactorKind::kRelativePose && mark[e.key(0)] && mark[e.key(1)]) continue;
        to_relinearize.push_back(f);  // not invariant: relinearised at the moved θ
        for (int k = 0; k < e.arity(); ++k)
          if (!fixed[e.key(k)]) to_touch.push_back(e.key(k));
      }
    }
    for (int v : poses) mark[v] = 0;
  }

  TreeMemory memory() const {
    TreeMemory m;
    double sep_sum = 0;
    for (const Clique& c : cliques) {
      m.clique_bytes_reserved += (c.storage.capacity() + c.pending.size()) * sizeof(double);
      if (!c.in_use) {
        ++m.free_cliques;
        continue;
      }
      ++m.cliques;
      m.clique_bytes += (c.storage.size() + c.pending.size()) * sizeof(double);
      m.max_frontal_dim = std::max(m.max_frontal_dim, c.F);
      m.max_separator_dim = std::max(m.max_separator_dim, c.Sn);
      sep_sum += c.Sn;
    }
    if (m.cliques > 0) m.mean_separator_dim = sep_sum / m.cliques;
    m.scratch_bytes =
        (extend_buf.capacity() + w_buf.capacity() + w_parent_buf.capacity()) * sizeof(double);
    for (const Lane& l : threads.lanes)
      m.scratch_bytes += (l.h.capacity() + l.diag.capacity() + l.x.capacity()) * sizeof(double);
    for (const auto& b : s_buffers) m.scratch_bytes += b.capacity() * sizeof(double);
    return m;
  }

  int addPose(const G& x, bool is_fixed) {
    if (!isFinitePose(x)) throw std::invalid_argument("IncrementalSmoother::addPose: not finite");
    const int index = numPoses();
    theta.push_back(x);
    fixed.push_back(is_fixed);
    delta.push_back(Vec::Zero());
    delta_newton.push_back(Vec::Zero());
    delta_seen.push_back(Vec::Zero());
    clique_of.push_back(-1);
    var_factors.emplace_back();
    slot.push_back(-1);
    for (size_t l = 1; l < threads.lanes.size(); ++l) threads.lanes[l].slot.push_back(-1);
    mark.push_back(0);
    changed.push_back(0);
    if (!is_fixed) new_vars.push_back(index);
    return index;
  }

  void addFactor(const Factor<G>& f) {
    std::string where = std::string("IncrementalSmoother::addFactor(") + toString(f.kind());
    for (int k = 0; k < f.arity(); ++k) where += (k ? ", " : " ") + std::to_string(f.key(k));
    where += "): ";
    for (int k = 0; k < f.arity(); ++k)
      if (f.key(k) < 0 || f.key(k) >= numPoses())
        throw std::invalid_argument(where + "pose index out of range (" +
                                    std::to_string(numPoses()) + " poses)");
    if (f.arity() == 2 && f.key(0) == f.key(1)) throw std::invalid_argument(where + "self-loop");
    if (!f.isFinite()) throw std::invalid_argument(where + "measurement or information not finite");
    const std::string problem =
        std::visit([](const auto& x) { return informationProblem(x.information); }, f.variant());
    if (!problem.empty()) throw std::invalid_argument(where + "information matrix " + problem);
    queued.push_back(f);
  }

  void linearize(int f) {
    typename Factor<G>::Linearization A;
    edges[f].linearize(theta, &A);
    LinearFactor& L = lin[f];
    const int n = edges[f].arity();
    for (int k = 0; k < n; ++k) {
      for (int l = 0; l <= k; ++l) L.H[L.block(k, l)].noalias() = A.A[k].transpose() * A.A[l];
      L.g[k].noalias() = -A.A[k].transpose() * A.r;
    }
  }

  // Whether factor f is assembled into the clique whose slots are `slot` at its frontal v (at
  // slot a): every non-fixed key of f lies in the clique, and v is the first of them (the
  // others were not eliminated before v). The one rule of where a factor's terms enter the tree.
  bool assembledAt(const Factor<G>& f, int v, const std::vector<int>& slot) const {
    const int a = slot[v];
    for (int k = 0; k < f.arity(); ++k) {
      const int o = f.key(k);
      if (o == v || fixed[o]) continue;
      if (slot[o] <= a) return false;  // below (in a child's cached factor), or added from o
    }
    return true;
  }

  // linearize(f) for every f of `factors`, in chunks shared among the threads when many, side
  // by side with `alongside` (if any: a task that does not read the linearised factors).
  void linearizeAll(const std::vector<int>& factors, const std::function<void()>& alongside = {}) {
    constexpr int kChunk = 128;
    constexpr int kMinSharedChunks = 4;  // fewer factors are linearised in well under 0.1 ms
    const int n = static_cast<int>(factors.size());
    const int chunks = (n + kChunk - 1) / kChunk;
    std::vector<int>& items = ready_scratch;
    items.clear();
    for (int k = 0; k < chunks; ++k) items.push_back(k);
    if (alongside) items.push_back(chunks);  // taken first (the pool is a stack)
    threads.workers.run(
        items,
        [&](int, int k) {
          if (k == chunks) {
            alongside();
          } else {
            for (int i = k * kChunk; i < std::min(n, (k + 1) * kChunk); ++i) linearize(factors[i]);
          }
          return -1;
        },
        /*share=*/chunks >= kMinSharedChunks);
  }

  bool exceedsThreshold(const Vec& dx) const {
    return dx.template head<kTrans>().cwiseAbs().maxCoeff() >
               opt.relinearize_threshold_translation ||
           dx.template tail<D - kTrans>().cwiseAbs().maxCoeff() >
               opt.relinearize_threshold_rotation;
  }

  int allocClique() {
    ++num_cliques;
    if (!free_cliques.empty()) {
      const int id = free_cliques.back();
      free_cliques.pop_back();
      cliques[id].in_use = true;
      cliques[id].removed_stamp = -1;
      return id;
    }
    cliques.emplace_back();
    cliques.back().in_use = true;
    return static_cast<int>(cliques.size()) - 1;
  }

  void freeClique(int id) {
    --num_cliques;
    Clique& c = cliques[id];
    c.frontals.clear();
    c.separator.clear();
    c.children.clear();
    c.parent = -1;
    c.dirty = false;
    c.damped = false;
    c.in_use = false;
    c.pending.resize(0, 0);
    c.pending_cols = 0;
    free_cliques.push_back(id);
  }

  std::vector<int>& slotsOf(int lane) { return lane == 0 ? slot : threads.lanes[lane].slot; }

  // slots[v] = v's position (in variables) among the clique's frontals then separator, until
  // clearSlots.
  static void setSlots(const Clique& c, std::vector<int>* slots) {
    const int nf = static_cast<int>(c.frontals.size());
    for (int a = 0; a < nf; ++a) (*slots)[c.frontals[a]] = a;
    for (int b = 0; b < static_cast<int>(c.separator.size()); ++b)
      (*slots)[c.separator[b]] = nf + b;
  }
  static void clearSlots(const Clique& c, std::vector<int>* slots) {
    for (int v : c.frontals) (*slots)[v] = -1;
    for (int v : c.separator) (*slots)[v] = -1;
  }

  // The clique's Hessian [H g; gᵀ ·] over frontals ∪ separator, lower triangle, into the lane's
  // h ((N+1)×(N+1), column-major; g in row N).
  void assemble(const Clique& c, int lane) {
    for (int ch : c.children) cliques[ch].applyPending();
    const int nf = static_cast<int>(c.frontals.size());
    const int N = c.F + c.Sn;
    std::vector<int>& slot = slotsOf(lane);
    std::vector<int>& child_slots = threads.lanes[lane].child_slots;
    DoubleBuffer& h_buf = threads.lanes[lane].h;
    setSlots(c, &slot);
    const int lda = N + 1;
    h_buf.resize(static_cast<size_t>(lda) * lda);
    for (int j = 0; j < lda; ++j)  // only the lower triangle is used
      std::fill(h_buf.data() + static_cast<size_t>(j) * lda + j, h_buf.data() + (j + 1) * lda, 0.0);
    Eigen::Map<Eigen::MatrixXd> H(h_buf.data(), N + 1, N + 1);
    // The factors whose first eliminated variable is a frontal of this clique: H(p, q) and g_p
    // for every pair of their non-fixed keys (a fixed key is a constant).
    for (int a = 0; a < nf; ++a) {
      const int v = c.frontals[a];
      for (int f : var_factors[v]) {
        const Factor<G>& e = edges[f];
        if (!assembledAt(e, v, slot)) continue;
        const LinearFactor& L = lin[f];
        const int arity = e.arity();
        for (int k = 0; k < arity; ++k) {
          if (fixed[e.key(k)]) continue;
          const int sk = slot[e.key(k)] * D;
          H.row(N).template segment<D>(sk) += L.g[k].transpose();
          for (int l = 0; l < arity; ++l) {
            if (fixed[e.key(l)]) continue;
            const int sl = slot[e.key(l)] * D;
            if (sk >= sl) H.template block<D, D>(sk, sl) += L.at(k, l);  // lower triangle
          }
        }
      }
    }
    // The children's cached factors on their separators.
    for (int ch : c.children) {
      const Clique& k = cliques[ch];
      const int m = static_cast<int>(k.separator.size());
      child_slots.resize(m);
      for (int p = 0; p < m; ++p) child_slots[p] = slot[k.separator[p]] * D;
      const auto kH = k.cachedH();
      const auto kg = k.cachedG();
      // kH holds its lower triangle (and full diagonal blocks).
      for (int q = 0; q < m; ++q) {
        const int sq = child_slots[q];
        H.row(N).template segment<D>(sq) += kg.template segment<D>(q * D).transpose();
        for (int p = 0; p < m; ++p) {
          const int sp = child_slots[p];
          if (sp < sq) continue;
          if (p >= q)
            H.template block<D, D>(sp, sq) += kH.template block<D, D>(p * D, q * D);
          else
            H.template block<D, D>(sp, sq) += kH.template block<D, D>(q * D, p * D).transpose();
        }
      }
    }
    clearSlots(c, &slot);
  }

  // Dense Cholesky elimination of one clique (its children already eliminated): L = chol(H_ff),
  // R = Lᵀ, S = R⁻ᵀH_fs, d = R⁻ᵀg_f, cached factor (H_ss − SᵀS, g_s − Sᵀd). Returns true when
  // the frontal block was nearly singular and had to be damped (Levenberg-style).
  bool eliminateClique(int id, int lane) {
    Clique& c = cliques[id];
    c.allocate();
    const int F = c.F, Sn = c.Sn, N = F + Sn, lda = N + 1;
    assemble(c, lane);
    double* A = threads.lanes[lane].h.data();
    std::vector<double>& diag_buf = threads.lanes[lane].diag;
    diag_buf.resize(F);
    for (int k = 0; k < F; ++k) diag_buf[k] = A[static_cast<size_t>(k) * lda + k];
    bool damped = false;
    if (!partialCholesky(A, lda, F, N + 1, diag_buf.data())) {
      damped = true;
      double max_diag = 0;
      bool finite = true;
      for (int k = 0; k < F; ++k) {
        finite = finite && std::isfinite(diag_buf[k]);
        if (std::isfinite(diag_buf[k])) max_diag = std::max(max_diag, diag_buf[k]);
      }
      const double floor = std::max(1e-9 * max_diag, 1e-9);
      std::vector<double> base(F), damped_diag(F);
      for (int k = 0; k < F; ++k)
        base[k] = std::isfinite(diag_buf[k]) ? std::max(diag_buf[k], floor) : floor;
      bool ok = false;
      for (double lambda = 1e-6; lambda < 1e6 && !ok && finite; lambda *= 10) {
        assemble(c, lane);
        for (int k = 0; k < F; ++k) {
          A[static_cast<size_t>(k) * lda + k] += lambda * base[k];
          damped_diag[k] = A[static_cast<size_t>(k) * lda + k];
        }
        ok = partialCholesky(A, lda, F, N + 1, damped_diag.data());
      }
      if (!ok) {  // not even damping helps (non-finite input): pin the frontals at zero
        std::fill(c.storage.begin(), c.storage.end(), 0.0);
        for (int k = 0; k < F; ++k) c.lsPtr()[static_cast<size_t>(k) * c.ld + k] = std::sqrt(floor);
        c.dirty = true;
        c.damped = true;
        return true;
      }
    }
    // Copy out: LS = first F columns (rows 0..N−1), d = row N of them, the Schur complement.
    double* LS = c.lsPtr();
    for (int k = 0; k < F; ++k) {
      const double* col = A + static_cast<size_t>(k) * lda;
      double* out = LS + static_cast<size_t>(k) * c.ld;
      for (int i = 0; i < k; ++i) out[i] = 0.0;
      std::copy(col + k, col + N, out + k);
      c.dPtr()[k] = col[N];
    }
    double* cH = c.hPtr();
    double* cg = c.gPtr();
    for (int q = 0; q < Sn; ++q) {  // the lower triangle, then the diagonal blocks made full
      const double* col = A + static_cast<size_t>(F + q) * lda + F;
      std::copy(col + q, col + Sn, cH + static_cast<size_t>(q) * c.ldh + q);
      cg[q] = col[Sn];
    }
    for (int b = 0; b < Sn; b += D)
      for (int q = b; q < b + D; ++q)
        for (int p = b; p < q; ++p)
          cH[static_cast<size_t>(q) * c.ldh + p] = cH[static_cast<size_t>(p) * c.ldh + q];
    c.dirty = true;
    c.damped = damped;
    return damped;
  }

  // Tops of at least this many variables are ordered by nested dissection
  // (SmootherOptions::nested_dissection_min; automatic: 100 poses in 3D, never in 2D).
  int nestedDissectionMin() const {
    if (opt.nested_dissection_min >= 0) return opt.nested_dissection_min;
    return D == 6 ? 100 : std::numeric_limits<int>::max();
  }

  // Kaess 2012 Alg. 1 lines 5–7: order the removed top (CCOLAMD, or nested dissection when
  // large; `constrained` variables last), eliminate it into new cliques and re-attach the
  // orphaned subtrees. `to_linearize`: factors whose linearisation was left to this step.
  void eliminateTop(const std::vector<int>& top, const std::vector<int>& orphans, bool constrain,
                    const std::vector<int>& to_linearize, UpdateStats* st) {
    const int n = static_cast<int>(top.size());
    if (n == 0) return linearizeAll(to_linearize);
    for (int a = 0; a < n; ++a) slot[top[a]] = a;
    bayestree::RowList& rows = s_rows;
    rows.clear();
    // Factors with two or more non-fixed keys in the top, once each (from their first key in
    // the top's order; a unary factor adds no structure).
    for (int a = 0; a < n; ++a) {
      const int v = top[a];
      for (int f : var_factors[v]) {
        const Factor<G>& e = edges[f];
        int keys = 0;
        bool first = true;
        for (int k = 0; k < e.arity(); ++k) {
          const int o = e.key(k);
          if (fixed[o]) continue;
          ++keys;
          if (slot[o] < a) first = false;  // a key outside the top has slot −1: not first
        }
        if (keys < 2 || !first) continue;
        for (int k = 0; k < e.arity(); ++k)
          if (!fixed[e.key(k)]) rows.add(slot[e.key(k)]);
        rows.endRow();
      }
    }
    // Alg. 1 line 5: the orphans' cached factors join the factors of the top.
    for (int oc : orphans) {
      for (int v : cliques[oc].separator) rows.add(slot[v]);
      rows.endRow();
    }
    // iSAM2 §5: constrained ordering, the variables of the new factors eliminated last.
    std::vector<int>& group = s_group;
    group.assign(n, 0);
    if (constrain)
      for (int a = 0; a < n; ++a) group[a] = mark[top[a]] ? 1 : 0;
    // The ordering and symbolic elimination, side by side with the linearisation of the
    // relinearised factors (Alg. 2 line 3), which they do not need.
    bayestree::EliminationPlan plan;
    linearizeAll(to_linearize, [&] {
      plan = bayestree::planElimination(n, rows,
                                        n >= nestedDissectionMin()
                                            ? bayestree::constrainedNestedDissection(n, rows, group)
                                            : bayestree::constrainedColamd(n, rows, group));
    });

    const int m = static_cast<int>(plan.cliques.size());
    std::vector<int>& ids = s_ids;
    ids.resize(m);
    for (int k = 0; k < m; ++k) ids[k] = allocClique();
    for (int k = 0; k < m; ++k) {
      const bayestree::SymbolicClique& sc = plan.cliques[k];
      Clique& c = cliques[ids[k]];
      c.frontals.clear();
      c.separator.clear();
      c.children.clear();
      for (int a : sc.frontals) c.frontals.push_back(top[a]);
      for (int a : sc.separator) c.separator.push_back(top[a]);
      c.parent = sc.parent < 0 ? -1 : ids[sc.parent];
      for (int v : c.frontals) clique_of[v] = ids[k];
    }
    // Recycled cliques keep their storage: hand the largest buffers to the largest new cliques
    // (saves reallocating, and re-faulting, the big ones on every update).
    if (m > 1) {
      std::vector<int>& by_need = s_by_need;
      std::vector<int>& by_capacity = s_by_capacity;
      by_need.assign(ids.begin(), ids.end());
      by_capacity.assign(ids.begin(), ids.end());
      auto need = [&](int id) {
        const Clique& c = cliques[id];
        const int F = static_cast<int>(c.frontals.size()) * D;
        const int Sn = static_cast<int>(c.separator.size()) * D;
        return Clique::sizeFor(F, F + Sn, Sn);
      };
      std::sort(by_need.begin(), by_need.end(), [&](int a, int b) { return need(a) > need(b); });
      std::sort(by_capacity.begin(), by_capacity.end(), [&](int a, int b) {
        return cliques[a].storage.capacity() > cliques[b].storage.capacity();
      });
      s_buffers.resize(m);
      for (int k = 0; k < m; ++k) s_buffers[k].swap(cliques[by_capacity[k]].storage);
      for (int k = 0; k < m; ++k) cliques[by_need[k]].storage.swap(s_buffers[k]);
    }
    for (int k = 0; k < m; ++k) {
      const int parent = cliques[ids[k]].parent;
      if (parent < 0)
        roots.push_back(ids[k]);
      else
        cliques[parent].children.push_back(ids[k]);
    }
    // Alg. 1 line 7: each orphan hangs below the clique where the first eliminated variable of
    // its separator is frontal.
    for (int oc : orphans) {
      int first = n;
      for (int v : cliques[oc].separator) first = std::min(first, plan.position[slot[v]]);
      const int parent = ids[plan.clique_of_variable[plan.order[first]]];
      cliques[oc].parent = parent;
      cliques[parent].children.push_back(oc);
    }
    for (int a = 0; a < n; ++a) slot[top[a]] = -1;
    for (int k = 0; k < m; ++k) {  // children (new ones, and orphans) before parents
      Clique& c = cliques[ids[k]];
      const double F = static_cast<double>(c.frontals.size()) * D;
      c.subtree_entries = F * (F + static_cast<double>(c.separator.size()) * D);
      for (int ch : c.children) c.subtree_entries += cliques[ch].subtree_entries;
    }
    // Alg. 1 line 6: eliminate, children before parents: a clique is ready once its last child
    // is done, and independent subtrees go to different threads.
    std::unique_ptr<std::atomic<int>[]> children_left(new std::atomic<int>[m]);
    for (int k = 0; k < m; ++k) children_left[k].store(0, std::memory_order_relaxed);
    for (int k = 0; k < m; ++k)
      if (plan.cliques[k].parent >= 0)
        children_left[plan.cliques[k].parent].fetch_add(1, std::memory_order_relaxed);
    std::vector<int>& leaves = ready_scratch;
    leaves.clear();
    for (int k = m - 1; k >= 0; --k)
      if (children_left[k].load(std::memory_order_relaxed) == 0) leaves.push_back(k);
    for (Lane& l : threads.lanes) l.eliminated = l.indeterminate = 0;
    threads.workers.run(
        leaves,
        [&](int lane, int k) {
          ++threads.lanes[lane].eliminated;
          if (eliminateClique(ids[k], lane)) ++threads.lanes[lane].indeterminate;
          const int parent = plan.cliques[k].parent;
          return parent >= 0 && children_left[parent].fetch_sub(1, std::memory_order_acq_rel) == 1
                     ? parent
                     : -1;
        },
        /*share=*/offCriticalPathFlops(plan) >= kMinSharedElimination);
    for (size_t l = 0; l < threads.lanes.size(); ++l) {
      st->indeterminate_cliques += threads.lanes[l].indeterminate;
      if (l > 0) st->cliques_on_helpers += threads.lanes[l].eliminated;
    }
    st->cliques_reeliminated += m;
    st->variables_reeliminated += n;
  }

  // ---- Incremental factorisation of a factor between variables already in the tree ----
  // A factor whose ends are frontal in cliques on one path to the root changes the Bayes tree's
  // matrices only by a rank-D term: its whitened rows W (WWᵀ = [A r]ᵀ[A r]) are folded into the
  // clique of its first eliminated end by a rank-D Cholesky update, and what is left of W passes
  // on to the parent as the update of that clique's cached factor, up to the root (the
  // incremental factorisation of iSAM, Kaess, Ranganathan, Dellaert, T-RO 2008, applied clique
  // by clique). Nothing is re-ordered or re-eliminated: O(D·N·F) per clique on the path instead
  // of O(F·N²).

  bool isAncestorOrSelf(int ancestor, int c) const {
    for (; c >= 0; c = cliques[c].parent)
      if (c == ancestor) return true;
    return false;
  }

  // The clique of the first eliminated non-fixed end of factor f (−1 when the factor cannot be
  // folded in: an end not yet in the tree, ends in different branches, or a damped clique on
  // the way to the root). Folding one factor in leaves this unchanged for the others.
  int foldInClique(int f) const {
    const Factor<G>& e = edges[f];
    int lower = -1, upper = -1;
    for (int k = 0; k < e.arity(); ++k) {
      const int v = e.key(k);
      if (fixed[v]) continue;
      if (clique_of[v] < 0) return -1;
      (lower < 0 ? lower : upper) = v;
    }
    if (lower < 0) return -1;
    int start = clique_of[lower];
    if (upper >= 0 && !isAncestorOrSelf(clique_of[upper], start)) {
      if (!isAncestorOrSelf(start, clique_of[upper])) return -1;
      start = clique_of[upper];
    }
    for (int c = start; c >= 0; c = cliques[c].parent)
      if (cliques[c].damped) return -1;
    return start;
  }

  // Folding factor f in from clique `start`: its later end joins the separators on the way up
  // to its own clique (running intersection) until one already holds it. Sets *later to that
  // end and fills `path` with the cliques whose separator it joins (empty when none).
  void separatorsToExtend(int f, int start, int* later, std::vector<int>* path) const {
    const Factor<G>& e = edges[f];
    path->clear();
    *later = -1;
    if (e.arity() < 2) return;  // a unary factor lies in its clique already
    *later = clique_of[e.key(0)] == start && !fixed[e.key(0)] ? e.key(1) : e.key(0);
    if (fixed[*later]) return;
    for (int c = start; c != clique_of[*later]; c = cliques[c].parent) {
      const auto& sep = cliques[c].separator;
      if (std::find(sep.begin(), sep.end(), *later) != sep.end()) break;
      path->push_back(c);
    }
  }

  // Whether folding factor f in from clique `start` keeps every separator on the way within
  // its budget (the fill of separatorsToExtend, which only a re-elimination, with a fresh
  // ordering, keeps down).
  bool withinBudget(int f, int start) {
    int later;
    separatorsToExtend(f, start, &later, &s_path);
    for (int c : s_path)
      if (cliques[c].Sn + D > cliques[c].separatorBudget()) return false;
    return true;
  }

  // Rough flop counts that decide between folding factors in and re-eliminating their paths:
  // a rank-D update of a clique costs about 4·D·F·N (plus D·Sn² for its cached factor), a
  // re-elimination F³/3 + F²·Sn + F·Sn²; each also has a fixed cost per clique (assembly,
  // ordering, new storage: kCliqueOverhead to re-eliminate, a quarter of it to update).
  static constexpr double kCliqueOverhead = 4000;
  double foldFlops(int start) const {
    double flops = 0;
    for (int c = start; c >= 0; c = cliques[c].parent) {
      const double F = cliques[c].F, S = cliques[c].Sn;
      flops += 4.0 * D * F * (F + S) + D * S * S + kCliqueOverhead / 4;
    }
    return flops;
  }
  // The union of the paths from `starts` to the root, each clique counted once.
  double eliminationFlops(const std::vector<int>& starts) {
    ++path_stamp;
    double flops = 0;
    for (int start : starts)
      for (int c = start; c >= 0 && cliques[c].path_stamp != path_stamp; c = cliques[c].parent) {
        cliques[c].path_stamp = path_stamp;
        const double F = cliques[c].F, S = cliques[c].Sn;
        flops += F * F * F / 3 + F * F * S + F * S * S + kCliqueOverhead;
      }
    return flops;
  }

  // Folds factor f into the tree (foldInClique(f) ≥ 0); returns the cliques updated.
  int foldIn(int f) {
    const Factor<G>& e = edges[f];
    const int start = foldInClique(f);
    int later;
    separatorsToExtend(f, start, &later, &s_path);
    for (int c : s_path) cliques[c].extendSeparator(later, &extend_buf);
    // W over the start clique's variables and the right-hand side: [Aᵀ; −rᵀ].
    typename Factor<G>::Linearization A;
    e.linearize(theta, &A);
    using MatMap = Eigen::Map<Eigen::MatrixXd>;
    int rows = cliques[start].F + cliques[start].Sn + 1;
    {
      const Clique& c = cliques[start];
      w_buf.resize(static_cast<size_t>(rows) * D);
      MatMap W(w_buf.data(), rows, D);
      W.setZero();
      setSlots(c, &slot);
      for (int k = 0; k < e.arity(); ++k)
        if (!fixed[e.key(k)]) W.middleRows(slot[e.key(k)] * D, D) = A.A[k].transpose();
      clearSlots(c, &slot);
      W.row(rows - 1) = -A.r.transpose();
    }
    int updated = 0;
    for (int id = start;;) {
      Clique& c = cliques[id];
      const int Sn = c.Sn;
      c.rankUpdate(w_buf.data(), rows);  // leaves V = rows F..F+Sn of W
      ++updated;
      if (c.parent < 0) break;  // what is left is the constant term
      const auto V = MatMap(w_buf.data(), rows, D).bottomRows(Sn + 1);
      // The parent's W: V scattered to the parent's rows.
      const Clique& p = cliques[c.parent];
      const int Np = p.F + p.Sn;
      setSlots(p, &slot);
      w_parent_buf.resize(static_cast<size_t>(Np + 1) * D);
      MatMap Wp(w_parent_buf.data(), Np + 1, D);
      Wp.setZero();
      for (int b = 0; b < static_cast<int>(c.separator.size()); ++b)
        Wp.middleRows(slot[c.separator[b]] * D, D) = V.middleRows(b * D, D);
      Wp.row(Np) = V.row(Sn);
      clearSlots(p, &slot);
      w_buf.swap(w_parent_buf);
      rows = Np + 1;
      id = c.parent;
    }
    return updated;
  }

  // Work smaller than this stays on one thread (a helper's wake-up and the hand-over would cost
  // more than they save, tens of microseconds): an elimination with fewer flops off its critical
  // path (tuned on smallGrid3D, torus3D, parking-garage), a back-substitution subtree that reads
  // fewer entries (tuned on intel and parking-garage).
  static constexpr double kMinSharedElimination = 1e6;  // flops off the critical path

  // The flops of eliminating `plan` (F³/3 + F²·S + F·S² per clique) that lie off its critical
  // path (the costliest chain from a leaf to a root): what a second thread could take on.
  double offCriticalPathFlops(const bayestree::EliminationPlan& plan) {
    const int m = static_cast<int>(plan.cliques.size());
    std::vector<double>& chain = s_chain_flops;
    chain.assign(m, 0.0);
    double total = 0, critical = 0;
    for (int k = 0; k < m; ++k) {  // children before parents
      const bayestree::SymbolicClique& c = plan.cliques[k];
      const double F = static_cast<double>(c.frontals.size()) * D;
      const double S = static_cast<double>(c.separator.size()) * D;
      const double flops = F * F * F / 3 + F * F * S + F * S * S;
      total += flops;
      chain[k] += flops;
      critical = std::max(critical, chain[k]);
      if (c.parent >= 0) chain[c.parent] = std::max(chain[c.parent], chain[k]);
    }
    return total - critical;
  }
  static constexpr double kMinSharedSolve = 20000;  // entries of [L; Sᵀ] in the subtree

  // Kaess 2012 Alg. 3 (partial state update, "wildfire"): solve top-down from the roots,
  // entering a clique only if it was re-eliminated or a separator variable changed by at least
  // the threshold (`full`: every clique); returns the number of cliques solved. A clique is
  // ready once its parent is solved: independent subtrees go to different threads.
  void backSubstitute(bool full, UpdateStats* st) {
    auto needs_solving = [&](const Clique& c) {
      if (full || c.dirty) return true;
      for (int v : c.separator)
        if (changed[v]) return true;
      return false;
    };
    for (Lane& l : threads.lanes) l.solved = 0;
    // Depth-first from the roots on this thread, until a subtree worth sharing waits (the
    // oldest entry of the stack is the largest subtree waiting): small walks never involve a
    // helper.
    auto worth_sharing = [&](const std::deque<int>& pending) {
      return pending.size() > 1 && cliques[pending.front()].subtree_entries >= kMinSharedSolve;
    };
    // Solves the top of `lane`'s stack and stacks the children that need solving (a child's
    // separator lies in this clique's frontals ∪ separator, all solved by now).
    auto solve_next = [&](int lane) {
      std::deque<int>& stack = threads.lanes[lane].pending;
      const int c = stack.back();
      stack.pop_back();
      solveClique(c, full, &threads.lanes[lane]);
      for (int ch : cliques[c].children)
        if (needs_solving(cliques[ch])) stack.push_back(ch);
    };
    const bool can_share = threads.lanes.size() > 1;
    std::deque<int>& pending = threads.lanes[0].pending;
    pending.clear();
    for (int r : roots)
      if (needs_solving(cliques[r])) pending.push_back(r);
    while (!pending.empty() && !(can_share && worth_sharing(pending))) solve_next(0);
    // Then with the helpers: each thread walks a subtree depth-first on a stack of its own and
    // hands the oldest entry to a thread that has run out of work.
    if (!pending.empty()) {
      std::vector<int>& ready = ready_scratch;
      ready.assign(pending.begin(), pending.end());
      threads.workers.run(ready, [&](int lane, int id) {
        std::deque<int>& stack = threads.lanes[lane].pending;
        stack.assign(1, id);
        while (!stack.empty()) {
          solve_next(lane);
          if (worth_sharing(stack) && threads.workers.hungry()) {
            threads.workers.push(stack.front());
            stack.pop_front();
          }
        }
        return -1;
      });
    }
    for (size_t l = 0; l < threads.lanes.size(); ++l) {
      Lane& lane = threads.lanes[l];
      st->cliques_solved += lane.solved;
      if (l > 0) st->cliques_on_helpers += lane.solved;
      for (int v : lane.changed_list) changed[v] = 0;
      lane.changed_list.clear();
    }
  }

  // x_f = R⁻¹ (d − S x_s) for one clique, into Δ (Alg. 3); marks the frontals that moved by at
  // least the wildfire threshold as changed.
  void solveClique(int id, bool full, Lane* lane) {
    Clique& c = cliques[id];
    ++lane->solved;
    const int nf = static_cast<int>(c.frontals.size());
    const int ns = static_cast<int>(c.separator.size());
    const int F = c.F;
    // z = [x_f; x_s]: the separator's values in, the frontals' out (bayestree/dense_kernels.h).
    const int N = F + c.Sn;
    lane->x.resize(N);
    double* x = lane->x.data();
    for (int b = 0; b < ns; ++b) Eigen::Map<Vec>(x + F + b * D) = delta_newton[c.separator[b]];
    bayestree::solveConditional(c.lsPtr(), c.ld, N, F, c.dPtr(), x);
    // The new values are always taken. A variable is "changed" (the cliques below that hold it
    // in their separator must be recomputed) when it moved by at least the threshold from the
    // value they were last solved with (delta_seen), so small moves cannot accumulate.
    for (int a = 0; a < nf; ++a) {
      const int v = c.frontals[a];
      const Eigen::Map<const Vec> xv(x + a * D);
      if (full || (xv - delta_seen[v]).cwiseAbs().maxCoeff() >= opt.wildfire_threshold) {
        delta_seen[v] = xv;
        if (!changed[v]) {
          changed[v] = 1;
          lane->changed_list.push_back(v);
        }
      }
      delta_newton[v] = xv;
      if (!opt.dogleg) delta[v] = xv;
    }
    c.dirty = false;
  }

  // F at θ ⊞ x for every pose.
  double objectiveAt(const std::vector<Vec>& x) const {
    std::vector<G> poses(theta.size());
    for (size_t v = 0; v < theta.size(); ++v)
      poses[v] = fixed[v] ? theta[v] : theta[v].retract(x[v]);
    double f = 0;
    for (const Factor<G>& e : edges) f += e.cost(poses);
    return f;
  }

  // Powell's dogleg step on the Bayes tree (bayestree/dogleg_step.h) into Δ.
  void doglegStep() {
    delta = bayestree::doglegStep<D>(cliques, delta_newton, &dogleg_radius, opt.dogleg_min_radius,
                                     [&](const std::vector<Vec>& x) { return objectiveAt(x); });
  }

  // One update. When new poses arrive together with factors that a rank update could take (a
  // pose with its loop closures, --step pose), the factors that bring the new poses into the
  // tree go first (Alg. 1, re-eliminating the top) and the others are folded in after: the
  // linear system, hence the step, is that of one update with all of them.
  UpdateStats update(bool all) {
    if (!all) ++update_count;
    const bool relinearize_now = !all && update_count % opt.relinearize_skip == 0;
    if (all || !opt.rank_updates || opt.dogleg || new_vars.empty() || queued.size() < 2 ||
        !to_touch.empty())
      return updateStep(all, relinearize_now, true);
    std::vector<Factor<G>> rest = splitOffIntroducing();
    if (!worthFolding(rest)) {
      queued.insert(queued.end(), rest.begin(), rest.end());
      rest.clear();
    }
    if (rest.empty()) return updateStep(false, relinearize_now, true);
    const auto t0 = Clock::now();
    UpdateStats st = updateStep(false, relinearize_now, false);
    queued.swap(rest);
    accumulate(&st, updateStep(false, false, true));
    st.time_s = secondsSince(t0);
    return st;
  }

  // Whether folding `factors` in (after their new poses join the tree at the root) is estimated
  // cheaper than re-eliminating the paths from their old ends' cliques to the root with them.
  bool worthFolding(const std::vector<Factor<G>>& factors) {
    if (factors.empty()) return false;
    std::vector<int> starts;
    double fold_flops = 0;
    for (const Factor<G>& e : factors) {
      int start = -1;
      for (int k = 0; k < e.arity(); ++k) {
        const int v = e.key(k);
        if (!fixed[v] && clique_of[v] >= 0 && (start < 0 || isAncestorOrSelf(start, clique_of[v])))
          start = clique_of[v];
      }
      if (start < 0) return false;  // both ends new: no path to compare
      starts.push_back(start);
      fold_flops += foldFlops(start);
    }
    return fold_flops <= eliminationFlops(starts);
  }

  // Keeps in `queued` the factors that join each new pose to the tree (one per pose, or those
  // that cannot be told apart) and returns the others, whose ends will all be in the tree.
  std::vector<Factor<G>> splitOffIntroducing() {
    std::vector<Factor<G>> intro, rest;
    std::vector<char> placed(queued.size(), 0);
    std::vector<int> joined;  // new poses joined by a factor in `intro` (slot[v] = 1)
    auto known = [&](int v) { return fixed[v] || clique_of[v] >= 0 || slot[v] == 1; };
    for (bool progress = true; progress;) {
      progress = false;
      for (size_t k = 0; k < queued.size(); ++k) {
        if (placed[k]) continue;
        const Factor<G>& e = queued[k];
        const bool ki = known(e.key(0)), kj = e.arity() < 2 || known(e.key(1));
        if (ki && kj) {
          rest.push_back(e);
        } else if (e.arity() == 2 && (ki || kj)) {
          const int v = ki ? e.key(1) : e.key(0);
          slot[v] = 1;
          joined.push_back(v);
          intro.push_back(e);
        } else {
          continue;
        }
        placed[k] = 1;
        progress = true;
      }
    }
    for (size_t k = 0; k < queued.size(); ++k)
      if (!placed[k]) intro.push_back(queued[k]);
    for (int v : joined) slot[v] = -1;
    queued.swap(intro);
    return rest;
  }

  // Kaess 2012 Alg. 1 (with Alg. 2 fluid relinearisation when `relinearize_now`); `all`
  // relinearises every variable and re-eliminates the whole tree; `solve` runs the partial
  // state update (Alg. 3) at the end.
  UpdateStats updateStep(bool all, bool relinearize_now, bool solve) {
    const auto t0 = Clock::now();
    UpdateStats st;
    ++stamp;
    std::vector<int>& touched = s_touched;  // variables of the new factors, new variables
    touched.clear();
    auto touch = [&](int v) {
      if (!fixed[v] && !mark[v]) {
        mark[v] = 1;
        touched.push_back(v);
      }
    };
    // Alg. 1 line 1: add the new variables and factors.
    st.new_variables = static_cast<int>(new_vars.size());
    for (int v : new_vars) touch(v);
    new_vars.clear();
    // Variables whose cliques must be re-eliminated though no new factor touches them (a
    // released anchor's neighbours, the factors of moved poses: our extension, for the online
    // layer's components).
    const bool restructured = !to_touch.empty();
    for (int v : to_touch) touch(v);
    to_touch.clear();
    const int first_new = static_cast<int>(edges.size());
    for (const Factor<G>& e : queued) {
      const int f = static_cast<int>(edges.size());
      edges.push_back(e);
      lin.emplace_back();
      factor_stamp.push_back(-1);
      for (int k = 0; k < e.arity(); ++k) {
        var_factors[e.key(k)].push_back(f);
        touch(e.key(k));
      }
    }
    st.new_factors = static_cast<int>(queued.size());
    queued.clear();

    // Alg. 2 lines 1–2: every relinearize_skip updates, relinearise the variables whose Δ
    // exceeds β: θ ← θ ⊞ Δ.
    std::vector<int>& relin = s_relin;
    relin.clear();
    const int n = numPoses();
    if (all) {
      for (int v = 0; v < n; ++v)
        if (!fixed[v]) relin.push_back(v);
    } else if (relinearize_now) {
      for (int v = 0; v < n; ++v)
        if (!fixed[v] && clique_of[v] >= 0 && exceedsThreshold(delta[v])) relin.push_back(v);
    }
    for (int v : relin) {
      theta[v] = theta[v].retract(delta[v]);
      theta[v].normalize();
      delta[v].setZero();
      delta_newton[v].setZero();
      delta_seen[v].setZero();
    }
    st.variables_relinearized = static_cast<int>(relin.size());
    // Alg. 2 line 3: re-linearise the factors of the relinearised variables; Alg. 1 line 2:
    // linearise the new factors.
    std::vector<int>& to_linearize = s_linearize;
    to_linearize.clear();
    auto add = [&](int f) {
      if (factor_stamp[f] == stamp) return;
      factor_stamp[f] = stamp;
      to_linearize.push_back(f);
    };
    for (int v : relin)
      for (int f : var_factors[v]) add(f);
    for (int f : to_relinearize) add(f);
    to_relinearize.clear();
    for (int f = first_new; f < static_cast<int>(edges.size()); ++f) add(f);
    // With variables relinearised the top is re-eliminated: its ordering can run while the
    // factors are linearised (eliminateTop); otherwise (few new factors) linearise them now.
    if (relin.empty()) {
      linearizeAll(to_linearize);
      to_linearize.clear();
    }

    // Only factors between variables already in the tree, nothing relinearised: fold them in by
    // rank updates along their paths to the root; otherwise re-eliminate the top (Alg. 1).
    const bool folded = !all && relin.empty() && !restructured && st.new_variables == 0 &&
                        st.new_factors > 0 && opt.rank_updates && foldInNewFactors(first_new, &st);
    const bool tree_changed = folded || reeliminateTop(relin, all, to_linearize, &st);
    for (int v : touched) mark[v] = 0;
    // Alg. 1 line 8 / Alg. 3: partial state update.
    if (solve) {
      backSubstitute(all || opt.full_backsubstitution, &st);
      if (opt.dogleg && tree_changed) doglegStep();
    }
    st.time_s = secondsSince(t0);
    return st;
  }

  // Folds the factors from first_new on into the tree when every one of them can be (within
  // its separators' budget: checked for all before the first is folded in); false otherwise.
  bool foldInNewFactors(int first_new, UpdateStats* st) {
    for (int f = first_new; f < static_cast<int>(edges.size()); ++f) {
      const int start = foldInClique(f);
      if (start < 0 || !withinBudget(f, start)) return false;
    }
    for (int f = first_new; f < static_cast<int>(edges.size()); ++f)
      st->cliques_updated += foldIn(f);
    return true;
  }

  // Kaess 2012 Alg. 1 lines 3–7 for the marked variables (s_touched, and `relin` relinearised;
  // `all`: every clique); returns whether there was a top to re-eliminate.
  bool reeliminateTop(const std::vector<int>& relin, bool all, const std::vector<int>& to_linearize,
                      UpdateStats* st) {
    const std::vector<int>& touched = s_touched;
    // Alg. 1 line 3 / Alg. 2 line 4: mark the cliques that contain a touched variable as
    // frontal and, for relinearised variables, every clique that contains it at all (the
    // subtree below its frontal clique where it appears in the separator).
    std::vector<int>& marked = s_marked;
    marked.clear();
    for (int v : touched)
      if (clique_of[v] >= 0) marked.push_back(clique_of[v]);
    if (all) {
      for (int c = 0; c < static_cast<int>(cliques.size()); ++c)
        if (cliques[c].in_use) marked.push_back(c);
    } else {
      std::vector<int>& stack = stack_scratch;
      stack.clear();
      for (int v : relin) {
        stack.push_back(clique_of[v]);
        while (!stack.empty()) {
          const int c = stack.back();
          stack.pop_back();
          marked.push_back(c);
          for (int ch : cliques[c].children) {
            const auto& sep = cliques[ch].separator;
            if (std::find(sep.begin(), sep.end(), v) != sep.end()) stack.push_back(ch);
          }
        }
      }
    }
    // Alg. 1 line 4: remove the top: the marked cliques and all their ancestors.
    std::vector<int>& removed = s_removed;
    removed.clear();
    for (int c : marked)
      while (c >= 0 && cliques[c].removed_stamp != stamp) {
        cliques[c].removed_stamp = stamp;
        removed.push_back(c);
        c = cliques[c].parent;
      }
    std::vector<int>& top = s_top;
    top.clear();
    for (int v : touched)
      if (clique_of[v] < 0) top.push_back(v);  // new variables
    std::vector<int>& orphans = s_orphans;     // subtrees off the top keep their cached factors
    orphans.clear();
    for (int c : removed) {
      for (int v : cliques[c].frontals) top.push_back(v);
      for (int ch : cliques[c].children)
        if (cliques[ch].removed_stamp != stamp) orphans.push_back(ch);
    }
    if (!removed.empty()) {
      roots.erase(std::remove_if(roots.begin(), roots.end(),
                                 [&](int r) { return cliques[r].removed_stamp == stamp; }),
                  roots.end());
      for (int c : removed) freeClique(c);
    }
    // Alg. 1 lines 5–7: re-order, re-eliminate the top, re-attach the orphans.
    eliminateTop(top, orphans, !all, to_linearize, st);
    for (int c : free_cliques) cliques[c].storage.fit(0);  // those not recycled hold no memory
    return !top.empty();
  }

  UpdateStats relinearizeAll() {
    const auto t0 = Clock::now();
    UpdateStats total;
    if (!queued.empty() || !new_vars.empty()) accumulate(&total, update(false));
    double F_prev = objectiveAt(delta);
    for (int it = 0; it < opt.finalize_max_iterations; ++it) {
      accumulate(&total, update(true));
      double F_new = objectiveAt(delta);
      if (!opt.dogleg && F_new > F_prev) {
        // Gauss–Newton overshoots: halve the step until F decreases (or give it up).
        std::vector<Vec> step = delta_newton;
        double scale = 1.0;
        for (int k = 0; k < 10 && F_new > F_prev; ++k) {
          scale *= 0.5;
          for (size_t v = 0; v < step.size(); ++v) delta[v] = scale * step[v];
          F_new = objectiveAt(delta);
        }
        if (F_new > F_prev) {
          for (Vec& v : delta) v.setZero();
          F_new = objectiveAt(delta);
        }
      }
      const double change = std::abs(F_prev - F_new) / std::max(F_prev, 1e-300);
      F_prev = F_new;
      if (change < opt.finalize_relative_tolerance) break;
    }
    total.time_s = secondsSince(t0);
    return total;
  }

  void checkInvariants() const {
    auto fail = [](const std::string& what) {
      throw std::logic_error("IncrementalSmoother invariant: " + what);
    };
    const int n = numPoses();
    const int nc = static_cast<int>(cliques.size());
    std::vector<int> frontal_count(n, 0);
    int in_use = 0;
    for (int id = 0; id < nc; ++id) {
      const Clique& c = cliques[id];
      if (!c.in_use) continue;
      ++in_use;
      const std::string name = "clique " + std::to_string(id);
      if (c.frontals.empty()) fail(name + " has no frontal variable");
      const int nf = static_cast<int>(c.frontals.size()), ns = static_cast<int>(c.separator.size());
      if (c.F != nf * D || c.Sn != ns * D || c.ld < c.F + c.Sn || c.ldh < c.Sn ||
          c.storage.size() != Clique::sizeFor(c.F, c.ld, c.ldh))
        fail(name + " has matrices of the wrong size");
      for (int v : c.frontals) {
        if (v < 0 || v >= n || fixed[v]) fail(name + " has a bad frontal " + std::to_string(v));
        ++frontal_count[v];
        if (clique_of[v] != id) fail("clique_of[" + std::to_string(v) + "] is not " + name);
        if (std::find(c.separator.begin(), c.separator.end(), v) != c.separator.end())
          fail(name + ": variable " + std::to_string(v) + " both frontal and separator");
      }
      if (c.parent < 0) {
        if (!c.separator.empty()) fail("root " + name + " has a non-empty separator");
        if (std::find(roots.begin(), roots.end(), id) == roots.end())
          fail(name + " has no parent but is not a root");
      } else {
        if (c.parent >= nc || !cliques[c.parent].in_use) fail(name + " has a dead parent");
        const Clique& p = cliques[c.parent];
        if (std::find(p.children.begin(), p.children.end(), id) == p.children.end())
          fail(name + " is not among its parent's children");
        // Running intersection: the separator lies in the parent's frontals ∪ separator.
        for (int v : c.separator)
          if (std::find(p.frontals.begin(), p.frontals.end(), v) == p.frontals.end() &&
              std::find(p.separator.begin(), p.separator.end(), v) == p.separator.end())
            fail(name + ": separator variable " + std::to_string(v) + " not in parent clique " +
                 std::to_string(c.parent));
        if (c.separator.empty()) fail(name + " has a parent but an empty separator");
      }
      for (int ch : c.children)
        if (ch < 0 || ch >= nc || !cliques[ch].in_use || cliques[ch].parent != id)
          fail(name + ": child " + std::to_string(ch) + " does not point back");
      // Acyclic: the root is reached within nc steps.
      int steps = 0;
      for (int p = c.parent; p >= 0; p = cliques[p].parent)
        if (++steps > nc) fail(name + " lies on a parent cycle");
    }
    if (in_use != num_cliques) fail("clique count mismatch");
    for (int r : roots)
      if (r < 0 || r >= nc || !cliques[r].in_use || cliques[r].parent != -1)
        fail("root " + std::to_string(r) + " is not a live parentless clique");
    for (int v = 0; v < n; ++v) {
      const bool eliminated =
          !fixed[v] && !mark[v] && std::find(new_vars.begin(), new_vars.end(), v) == new_vars.end();
      if (fixed[v] && frontal_count[v] != 0)
        fail("fixed pose " + std::to_string(v) + " is frontal");
      if (eliminated && frontal_count[v] != 1)
        fail("variable " + std::to_string(v) + " is frontal in " +
             std::to_string(frontal_count[v]) + " cliques");
    }
    // Every factor lies within the clique of its first eliminated variable: some non-fixed key's
    // clique holds every other non-fixed key.
    for (size_t f = 0; f < edges.size(); ++f) {
      const Factor<G>& e = edges[f];
      auto contains = [&](int c, int v) {
        const Clique& k = cliques[c];
        return std::find(k.frontals.begin(), k.frontals.end(), v) != k.frontals.end() ||
               std::find(k.separator.begin(), k.separator.end(), v) != k.separator.end();
      };
      bool held = false, any = false;
      for (int k = 0; k < e.arity() && !held; ++k) {
        const int v = e.key(k);
        if (fixed[v] || mark[v] || clique_of[v] < 0) continue;
        any = true;
        bool all = true;
        for (int l = 0; l < e.arity(); ++l)
          all = all && (fixed[e.key(l)] || contains(clique_of[v], e.key(l)));
        held = all;
      }
      if (any && !held) {
        std::string keys;
        for (int k = 0; k < e.arity(); ++k) keys += (k ? ", " : "") + std::to_string(e.key(k));
        fail("factor " + std::to_string(f) + " (" + keys + ") lies in no clique");
      }
    }
  }
};

template <class G>
IncrementalSmoother<G>::IncrementalSmoother(SmootherOptions options)
    : impl_(std::make_unique<Impl>(options)) {}
template <class G>
IncrementalSmoother<G>::~IncrementalSmoother() = default;
template <class G>
IncrementalSmoother<G>::IncrementalSmoother(const IncrementalSmoother& other)
    : impl_(std::make_unique<Impl>(*other.impl_)) {}
template <class G>
IncrementalSmoother<G>& IncrementalSmoother<G>::operator=(const IncrementalSmoother& other) {
  if (this != &other) impl_ = std::make_unique<Impl>(*other.impl_);
  return *this;
}
template <class G>
IncrementalSmoother<G>::IncrementalSmoother(IncrementalSmoother&&) noexcept = default;
template <class G>
IncrementalSmoother<G>& IncrementalSmoother<G>::operator=(IncrementalSmoother&&) noexcept = default;

template <class G>
int IncrementalSmoother<G>::addFixedPose(const G& value) {
  return impl_->addPose(value, true);
}
template <class G>
int IncrementalSmoother<G>::addPose(const G& initial) {
  return impl_->addPose(initial, false);
}
template <class G>
void IncrementalSmoother<G>::addFactor(const Factor<G>& factor) {
  impl_->addFactor(factor);
}
template <class G>
void IncrementalSmoother<G>::releaseFixedPose(int index) {
  impl_->releaseFixedPose(index);
}
template <class G>
void IncrementalSmoother<G>::transformPoses(const std::vector<int>& indices, const G& T) {
  impl_->transformPoses(indices, T);
}
template <class G>
UpdateStats IncrementalSmoother<G>::update() {
  return impl_->update(false);
}
template <class G>
UpdateStats IncrementalSmoother<G>::relinearizeAll() {
  return impl_->relinearizeAll();
}
template <class G>
std::vector<G> IncrementalSmoother<G>::estimate() const {
  std::vector<G> out(impl_->theta.size());
  for (size_t v = 0; v < out.size(); ++v) out[v] = estimate(static_cast<int>(v));
  return out;
}
template <class G>
G IncrementalSmoother<G>::estimate(int index) const {
  if (index < 0 || index >= impl_->numPoses())
    throw std::out_of_range("IncrementalSmoother::estimate: index " + std::to_string(index) +
                            " out of range");
  if (impl_->fixed[index]) return impl_->theta[index];
  return impl_->theta[index].retract(impl_->delta[index]);
}
template <class G>
const std::vector<G>& IncrementalSmoother<G>::linearizationPoint() const {
  return impl_->theta;
}
template <class G>
const std::vector<typename G::Tangent>& IncrementalSmoother<G>::delta() const {
  return impl_->delta;
}
template <class G>
double IncrementalSmoother<G>::objective() const {
  return impl_->objectiveAt(impl_->delta);
}
template <class G>
void IncrementalSmoother<G>::checkInvariants() const {
  impl_->checkInvariants();
}
template <class G>
int IncrementalSmoother<G>::numCliques() const {
  return impl_->num_cliques;
}
template <class G>
TreeMemory IncrementalSmoother<G>::memory() const {
  return impl_->memory();
}

template <class G>
int IncrementalSmoother<G>::numPoses() const {
  return impl_->numPoses();
}
template <class G>
int IncrementalSmoother<G>::numFactors() const {
  return static_cast<int>(impl_->edges.size());
}
template <class G>
bool IncrementalSmoother<G>::isFixed(int index) const {
  return index >= 0 && index < impl_->numPoses() && impl_->fixed[index];
}
template <class G>
const std::vector<Factor<G>>& IncrementalSmoother<G>::factors() const {
  return impl_->edges;
}
template <class G>
const SmootherOptions& IncrementalSmoother<G>::options() const {
  return impl_->opt;
}

template class IncrementalSmoother<SE2>;
template class IncrementalSmoother<SE3>;

}  // namespace arbor
