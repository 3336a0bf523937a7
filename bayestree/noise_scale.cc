#include "arbor_slam/bayestree/noise_scale.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <utility>

#include <boost/math/distributions/chi_squared.hpp>

namespace arbor {
namespace {

// The q-quantile of the first j of the sorted v (0 ≤ q ≤ 1, 0 < j ≤ v.size()): what selection
// (std::nth_element) of element ⌊q·j⌋ picks from them, in any order.
double quantileOfSorted(const std::vector<double>& sorted, size_t j, double q) {
  return sorted[std::min(j - 1, static_cast<size_t>(q * static_cast<double>(j)))];
}

}  // namespace

double chiSquareMedian(int dof) {
  return boost::math::quantile(boost::math::chi_squared_distribution<double>(dof), 0.5);
}

NoiseScaleCuts::NoiseScaleCuts(int dof, double c2, const NoiseScaleOptions& o)
    : t(o.tail_factor * c2) {
  const boost::math::chi_squared_distribution<double> chi2(dof);
  const double Ft = boost::math::cdf(chi2, t);
  q_median = boost::math::quantile(chi2, 0.5 * Ft);         // F⁻¹(F(t)/2)
  q_tail = boost::math::quantile(chi2, o.confidence * Ft);  // F⁻¹(q F(t))
  median = chiSquareMedian(dof);
}

NoiseScaleEstimate estimateNoiseScale(std::vector<double> m, int dof, double c2,
                                      const NoiseScaleOptions& o, bool from_median) {
  return estimateNoiseScale(std::move(m), NoiseScaleCuts(dof, c2, o), o, from_median);
}

NoiseScaleEstimate estimateNoiseScale(std::vector<double> m, const NoiseScaleCuts& cuts,
                                      const NoiseScaleOptions& o, bool from_median,
                                      double start_cap) {
  std::sort(m.begin(), m.end());  // m is ours
  return estimateNoiseScaleSorted(m, cuts, o, from_median, start_cap);
}

// The m ≤ t·σ² ("kept") are a prefix of the sorted m, so each step of the two fixed points is a
// binary search and an index, not a pass over m.
NoiseScaleEstimate estimateNoiseScaleSorted(const std::vector<double>& m,
                                            const NoiseScaleCuts& cuts, const NoiseScaleOptions& o,
                                            bool from_median, double start_cap) {
  const double t = cuts.t, q_median = cuts.q_median, q_tail = cuts.q_tail;
  auto within = [&](double bound) {  // how many m ≤ bound
    return static_cast<size_t>(std::upper_bound(m.begin(), m.end(), bound) - m.begin());
  };
  NoiseScaleEstimate out;
  double sigma2 = 1.0;
  if (from_median && !m.empty()) {  // the untruncated median: samples with few false ones
    const double start = quantileOfSorted(m, m.size(), 0.5) / cuts.median;
    if (start > 0 && std::isfinite(start)) sigma2 = std::min(start, start_cap);
  }
  size_t kept = 0;  // the m ≤ t·σ²: m[0, kept)
  auto keep = [&] {
    kept = within(t * sigma2);
    return kept >= 3;
  };
  if (!m.empty())
    out.share_at_word = static_cast<double>(within(t)) / static_cast<double>(m.size());
  // The median's fixed point.
  for (int round = 0; round < 50 && keep(); ++round) {
    const double next = quantileOfSorted(m, kept, 0.5) / q_median;
    const bool done = std::abs(next - sigma2) <= 1e-9 * sigma2;
    sigma2 = next;
    if (done || !(sigma2 > 0)) break;
  }
  if (!(sigma2 > 0) || !keep()) return out;
  // Loosening Ω (σ̂² > 1) takes a quarter of the innovations within the truncation at Ω's word, or
  // loosen_min_samples of them: else the median that climbed there may be of a few false
  // closures that drew it up.
  if (sigma2 > 1 && out.share_at_word < o.min_kept_share &&
      m.size() < static_cast<size_t>(o.loosen_min_samples))
    return out;
  out.estimated = true;
  // The tail's fixed point, within max_tail_scale of the median's, once enough are kept for its
  // quantile to be more than their largest.
  const double median_sigma2 = sigma2;
  out.median_sigma2 = median_sigma2;
  if (kept < static_cast<size_t>(o.tail_min_samples)) {
    out.sigma2 = sigma2;
    return out;
  }
  for (int round = 0; round < 50 && keep(); ++round) {
    const double next = std::max(sigma2, quantileOfSorted(m, kept, o.confidence) / q_tail);
    if (next > o.max_tail_scale * median_sigma2) {
      out.tail_cut = true;
      sigma2 = median_sigma2;
      break;
    }
    const bool done = next - sigma2 <= 1e-9 * sigma2;
    sigma2 = next;
    if (done) break;
  }
  out.sigma2 = sigma2;
  return out;
}

}  // namespace arbor
