#include "arbor_slam/tools/bench/robust_bench.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <ostream>
#include <set>
#include <sstream>
#include <stdexcept>
#include <tuple>
#include <variant>

#include "arbor_slam/core/initialization.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tools/bench/format.h"
#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/online_threshold.h"
#include "arbor_slam/tools/refine/batch_solvers.h"

namespace arbor::bench {
namespace {

namespace fs = std::filesystem;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// "0.1" for 0.1: the shortest form a reader would type.
std::string fractionText(double fraction) {
  std::ostringstream os;
  os << fraction;
  return os.str();
}

// Splits NAME at its policy: "M3500_group_0.1" → base "M3500", policy "group", fraction 0.1.
bool parseCaseName(const std::string& name, RobustCase* c) {
  for (const char* policy : {"random", "local", "group"}) {
    const std::string tag = std::string("_") + policy + "_";
    const size_t at = name.rfind(tag);
    if (at == std::string::npos || at == 0) continue;
    c->base = name.substr(0, at);
    c->policy = policy;
    const std::string rest = name.substr(at + tag.size());
    char* end = nullptr;
    const double f = std::strtod(rest.c_str(), &end);
    c->fraction = end != rest.c_str() ? f : kNaN;
    return true;
  }
  return false;
}

// The estimate's start: the file's vertices, else the odometry chain (`arbor batch`'s default).
template <class G>
std::vector<G> fileStart(const PoseGraph<G>& graph) {
  return initialize(graph, graph.has_initial_estimate ? InitMethod::kFile : InitMethod::kOdometry);
}

template <class G>
using Hook = std::function<RobustEstimate<G>(const PoseGraph<G>&)>;
const Hook<SE2>& robustHook(const RobustReplayHooks& h, const SE2*) { return h.robust2; }
const Hook<SE3>& robustHook(const RobustReplayHooks& h, const SE3*) { return h.robust3; }
const std::function<CleanReplayFigures(const PoseGraph2&)>& cleanHook(const RobustReplayHooks& h,
                                                                      const SE2*) {
  return h.clean2;
}
const std::function<CleanReplayFigures(const PoseGraph3&)>& cleanHook(const RobustReplayHooks& h,
                                                                      const SE3*) {
  return h.clean3;
}

// Runs `method` and judges what it returns; an exception becomes a failed figure.
template <class G, class Method>
RobustFigures runAndJudge(const PoseGraph<G>& graph, const std::vector<LabelPair>& labels,
                          const CleanReference<G>& ref, Method method) {
  try {
    return judgeEstimate(graph, method(graph), labels, ref);
  } catch (const std::exception& e) {
    RobustFigures f;
    f.error = e.what();
    return f;
  }
}

// The median and the largest eᵀΩe of the loop closures (|i − j| > 1) at `poses`; NaN without
// any.
template <class G>
std::pair<double, double> closureChi2(const PoseGraph<G>& graph, const std::vector<G>& poses) {
  std::vector<double> chi2;
  for (const auto& e : graph.edges) {
    if (std::abs(e.i - e.j) > 1) chi2.push_back(e.cost(poses[e.i], poses[e.j]));
  }
  if (chi2.empty()) return {kNaN, kNaN};
  std::sort(chi2.begin(), chi2.end());
  const size_t n = chi2.size();
  const double median = n % 2 ? chi2[n / 2] : 0.5 * (chi2[n / 2 - 1] + chi2[n / 2]);
  return {median, chi2.back()};
}

using AnyReference = std::variant<CleanReference<SE2>, CleanReference<SE3>>;

std::string orDash(double v, const char* format) {
  return std::isfinite(v) ? fmt(format, v) : std::string("—");
}

// "F/F* · ATE · P · R" of a judged estimate.
std::string quality(const RobustFigures& f) {
  if (!f.ok) return "failed";
  return orDash(f.F_ratio, "%.6g") + " · " + orDash(f.ate, "%.3g") + " · " +
         orDash(f.score.precision, "%.3f") + " · " + orDash(f.score.recall, "%.3f");
}

std::string anchorCell(const std::optional<RobustAnchor>& a) {
  if (!a) return "—";
  if (a->status != "ok") return a->status;
  return orDash(a->F_ratio, "%.4g") + " · " + orDash(a->ate, "%.3g") + " · " +
         orDash(a->precision, "%.3f") + " · " + orDash(a->recall, "%.3f") + " · " +
         fmt("%.3g", a->total_s);
}

}  // namespace

std::vector<RobustCase> sharedRobustCases(const std::string& shared_dir) {
  std::vector<RobustCase> cases;
  const fs::path dir = fs::path(shared_dir) / "datasets" / "robust";
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return cases;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    if (entry.path().extension() != ".g2o") continue;
    RobustCase c;
    c.name = entry.path().stem().string();
    c.file = entry.path().string();
    c.labels = fs::path(entry.path()).replace_extension(".labels").string();
    if (!fs::exists(c.labels, ec) || !parseCaseName(c.name, &c)) continue;
    c.base_file = (fs::path(shared_dir) / "datasets" / (c.base + ".g2o")).string();
    cases.push_back(c);
  }
  std::sort(cases.begin(), cases.end(), [](const RobustCase& a, const RobustCase& b) {
    return fs::file_size(a.file) < fs::file_size(b.file);
  });
  return cases;
}

template <class G>
std::vector<RobustCase> plantRobustCases(PoseGraph<G> graph, const RobustCase& like,
                                         const std::vector<double>& fractions,
                                         const std::vector<sim::OutlierPolicy>& policies,
                                         std::uint64_t seed, const std::string& out_dir,
                                         const std::string& suffix) {
  // As `arbor generate outliers`: a file without VERTEX lines gets its odometry chain.
  if (!graph.has_initial_estimate) graph.poses = odometryInitialization(graph);
  std::vector<RobustCase> cases;
  for (const double fraction : fractions) {
    for (const sim::OutlierPolicy policy : policies) {
      sim::OutlierOptions options;
      options.fraction = fraction;
      options.policy = policy;
      options.seed = seed;
      const auto planted = sim::addFalseClosures(graph, options);
      RobustCase c = like;
      c.policy = sim::toString(policy);
      c.fraction = fraction;
      c.name = like.base + "_" + c.policy + "_" + fractionText(fraction) + suffix;
      c.file = (fs::path(out_dir) / (c.name + ".g2o")).string();
      c.labels = (fs::path(out_dir) / (c.name + ".labels")).string();
      std::vector<LabelPair> labels;
      for (const auto& [i, j] : planted.pairs) labels.emplace_back(graph.ids[i], graph.ids[j]);
      writeG2oFile(c.file, planted.graph, planted.graph.poses);
      writeLabelsFile(c.labels, labels);
      cases.push_back(c);
    }
  }
  return cases;
}

std::vector<RobustCase> generateRobustCases(const std::string& shared_dir,
                                            const GenerationPlan& plan, const std::string& out_dir,
                                            std::vector<std::string>* missing) {
  std::vector<RobustCase> cases;
  for (const std::string& base : plan.bases) {
    const std::string base_file = (fs::path(shared_dir) / "datasets" / (base + ".g2o")).string();
    std::error_code ec;
    if (!fs::exists(base_file, ec)) {
      if (missing) missing->push_back(base);
      continue;
    }
    const LoadedDataset d = loadDataset(base_file);
    RobustCase like;
    like.base = base;
    like.base_file = base_file;
    like.generated = true;
    std::visit(
        [&](const auto& graph) {
          const auto planted =
              plantRobustCases(graph, like, plan.fractions, plan.policies, plan.seed, out_dir,
                               "_seed" + std::to_string(plan.seed));
          cases.insert(cases.end(), planted.begin(), planted.end());
        },
        d.graph);
  }
  return cases;
}

std::vector<RobustCase> selectCases(const std::vector<RobustCase>& cases, const std::string& only) {
  std::set<std::string> wanted;
  std::stringstream list(only);
  for (std::string item; std::getline(list, item, ',');) {
    if (!item.empty()) wanted.insert(item);
  }
  if (wanted.empty()) return cases;
  std::vector<RobustCase> selected;
  for (const RobustCase& c : cases) {
    if (wanted.count(c.name) || wanted.count(c.base)) selected.push_back(c);
  }
  return selected;
}

std::map<std::pair<std::string, std::string>, RobustAnchor> readRobustAnchorTable(
    const std::string& shared_dir) {
  std::map<std::pair<std::string, std::string>, RobustAnchor> table;
  auto number = [](const std::string& s) {
    char* end = nullptr;
    const double v = std::strtod(s.c_str(), &end);
    return end != s.c_str() ? v : kNaN;
  };
  for (const std::vector<std::string>& f : readReferenceRows(shared_dir, "robust-anchors.tsv")) {
    // dataset tool total_s p50_ms p99_ms max_ms rejected status F_clean F_clean/F* ate
    // precision recall
    if (f.size() < 13) continue;
    RobustAnchor a;
    a.total_s = number(f[2]);
    a.p50_ms = number(f[3]);
    a.p99_ms = number(f[4]);
    a.max_ms = number(f[5]);
    a.rejected = std::isfinite(number(f[6])) ? static_cast<int>(number(f[6])) : 0;
    a.status = f[7];
    a.F_clean = number(f[8]);
    a.F_ratio = number(f[9]);
    a.ate = number(f[10]);
    a.precision = number(f[11]);
    a.recall = number(f[12]);
    table[{f[0], f[1]}] = a;
  }
  return table;
}

template <class G>
RobustEstimate<G> robustBatch(const PoseGraph<G>& graph, const RobustBatchSettings& settings) {
  const cli::Stopwatch watch;
  RobustEstimate<G> out;
  GncResult gnc;
  double take_back = 0;  // certifyInliers' take-back bound (0: GNC's c²)
  if (settings.start == BatchStart::kOnline) {
    cli::OnlineBatch b = cli::solveGncFromReplay(graph, settings.gnc, {}, true, &out.poses);
    gnc = std::move(b.gnc);
    take_back = b.online.c2_take_back;
    out.note = "online: " + std::to_string(b.known_outliers) + " held out, " +
               std::to_string(b.readmitted) + " taken back; " + gnc.message;
  } else {
    out.poses = fileStart(graph);
    gnc = solveGnc(graph, &out.poses, settings.gnc);
    out.note = gnc.message;
  }
  if (settings.certify) {
    const CertifiedInliers c =
        certifyInliers(graph, &gnc, &out.poses, RtrOptions{}, /*max_passes=*/5, take_back);
    out.note +=
        std::string("; rtr ") +
        (c.rtr.certified ? "certified"
                         : (c.rtr.relaxation_solved ? "relaxation not exact" : "not certified")) +
        ", " + std::to_string(c.readmitted) + " readmitted";
  }
  out.total_s = watch.seconds();
  out.steps = gnc.iterations;
  out.rejected.assign(graph.edges.size(), 0);
  for (size_t k = 0; k < graph.edges.size(); ++k)
    out.rejected[k] = !gnc.trusted[k] && !gnc.inlier[k];
  return out;
}

template <class G>
CleanReference<G> cleanReference(PoseGraph<G> base, double F_star) {
  CleanReference<G> ref;
  ref.base = std::move(base);
  ref.F_star = F_star;
  ref.optimum = fileStart(ref.base);
  refine::runBatchSolver(refine::BatchSolver::kLevenbergMarquardt, ref.base, &ref.optimum);
  ref.F = objective(ref.base, ref.optimum);
  ref.method = "lm";
  if (!(ref.F <= F_star * (1 + 1e-3))) {
    std::vector<G> certified;
    try {
      refine::runBatchSolver(refine::BatchSolver::kRtr, ref.base, &certified);
      const double F = objective(ref.base, certified);
      if (F < ref.F) {
        ref.optimum = std::move(certified);
        ref.F = F;
        ref.method = "rtr";
      }
    } catch (const std::exception&) {
      // keep LM's answer; the notes show its F against F*
    }
  }
  return ref;
}

template <class G>
RobustFigures judgeEstimate(const PoseGraph<G>& graph, const RobustEstimate<G>& estimate,
                            const std::vector<LabelPair>& labels, const CleanReference<G>& ref) {
  RobustFigures f;
  f.total_s = estimate.total_s;
  f.steps = estimate.steps;
  f.latency = estimate.latency;
  f.note = estimate.note;
  try {
    const std::vector<G> on_base = posesByIds(graph, estimate.poses, ref.base);
    f.F_clean = objective(ref.base, on_base);
    if (std::isfinite(ref.F_star) && ref.F_star > 0) f.F_ratio = f.F_clean / ref.F_star;
    f.ate = alignedAte(on_base, ref.optimum);
    f.score = scoreRejections(rejectedPairs(graph, estimate.rejected), labels);
    f.ok = true;
  } catch (const std::exception& e) {
    f.error = e.what();
  }
  return f;
}

std::vector<RobustRow> runRobustBench(
    const std::vector<RobustCase>& cases, const std::map<std::string, Reference>& optimum,
    const std::map<std::pair<std::string, std::string>, RobustAnchor>& anchors,
    const RobustBatchSettings& settings, const RobustReplayHooks& hooks, std::ostream* progress) {
  std::map<std::string, AnyReference> references;
  std::map<std::string, std::optional<CleanReplayFigures>> clean_replays;
  std::vector<RobustRow> rows;
  for (const RobustCase& c : cases) {
    RobustRow row;
    row.c = c;
    const auto star = optimum.find(c.base);
    row.F_star = star == optimum.end() ? kNaN : star->second.F_star;
    if (!c.generated) {
      const auto gnc = anchors.find({c.name, "gnc"});
      if (gnc != anchors.end()) row.gnc = gnc->second;
      const auto risam = anchors.find({c.name, "risam"});
      if (risam != anchors.end()) row.risam = risam->second;
      const auto cauchy = anchors.find({c.name, "isam2_cauchy"});
      if (cauchy != anchors.end()) row.isam2_cauchy = cauchy->second;
    }
    try {
      const LoadedDataset d = loadDataset(c.file);
      const std::vector<LabelPair> labels = readLabelsFile(c.labels);
      row.false_edges = static_cast<int>(labels.size());
      std::visit(
          [&](const auto& graph) {
            using G = typename std::decay_t<decltype(graph)>::GroupType;
            auto cached = references.find(c.base);
            if (cached == references.end()) {
              const LoadedDataset b = loadDataset(c.base_file);
              const auto* base = std::get_if<PoseGraph<G>>(&b.graph);
              if (!base)
                throw std::runtime_error(c.base_file + " is not of the dimension of " + c.file);
              CleanReference<G> reference = cleanReference(*base, row.F_star);
              // A family's world has no optimum.tsv row: its F* is the clean optimum found.
              if (!c.family.empty() && !std::isfinite(reference.F_star))
                reference.F_star = reference.F;
              cached = references.emplace(c.base, std::move(reference)).first;
            }
            const auto* ref = std::get_if<CleanReference<G>>(&cached->second);
            if (!ref)
              throw std::runtime_error(c.base_file + " is not of the dimension of " + c.file);
            row.dim = G::kDim;
            row.poses = graph.numPoses();
            row.edges = graph.numEdges();
            row.loop_closures = sim::countLoopClosures(ref->base);
            row.F_reference = ref->F;
            row.F_star = ref->F_star;
            std::tie(row.closure_chi2_median, row.closure_chi2_max) =
                closureChi2(ref->base, ref->optimum);
            row.reference_method = ref->method;
            row.batch = runAndJudge(graph, labels, *ref, [&](const PoseGraph<G>& g) {
              return robustBatch(g, settings);
            });
            const auto& robust = robustHook(hooks, static_cast<const G*>(nullptr));
            if (robust) row.replay = runAndJudge(graph, labels, *ref, robust);
            const auto& clean = cleanHook(hooks, static_cast<const G*>(nullptr));
            if (clean) {
              auto replay = clean_replays.find(c.base);
              if (replay == clean_replays.end()) {
                std::optional<CleanReplayFigures> figures;
                try {
                  figures = clean(ref->base);
                } catch (const std::exception&) {
                  // no denominator for this base: the cost ratios show "—"
                }
                replay = clean_replays.emplace(c.base, figures).first;
              }
              row.clean_replay = replay->second;
            }
          },
          d.graph);
    } catch (const std::exception& e) {
      row.error = e.what();
    }
    if (progress) {
      *progress << "arbor bench robust: " << c.name << ": ";
      if (!row.error.empty()) {
        *progress << row.error;
      } else if (!row.batch.ok) {
        *progress << "batch failed: " << row.batch.error;
      } else {
        *progress << "batch " << fmt("%.3f", row.batch.total_s) << " s, F/F* "
                  << orDash(row.batch.F_ratio, "%.6g") << ", P "
                  << orDash(row.batch.score.precision, "%.3f") << ", R "
                  << orDash(row.batch.score.recall, "%.3f");
      }
      *progress << std::endl;
    }
    rows.push_back(std::move(row));
  }
  return rows;
}

namespace {

// Issue 14: "Every file with 10% or 50% false closures, every policy, 2D and 3D: F over the
// clean edges within 1% of the clean F*, precision ≥ 0.95 and recall ≥ 0.95 [...]. 90% random
// on the 2D sets: the same."
bool qualityGoalCovers(const RobustRow& r) {
  return r.c.fraction <= 0.5 + 1e-9 || (r.dim == 2 && r.c.policy == "random");
}

// "robust replay total at most 2× the clean replay's and p99 at most 3× on every file"
struct CostRatios {
  double total = std::numeric_limits<double>::quiet_NaN();
  double p99 = std::numeric_limits<double>::quiet_NaN();
};

std::optional<CostRatios> costRatios(const RobustRow& r) {
  if (!r.replay || !r.replay->ok || !r.replay->latency || !r.clean_replay) return std::nullopt;
  const CleanReplayFigures& c = *r.clean_replay;
  if (!(c.total_s > 0) || !(c.latency.p99 > 0)) return std::nullopt;
  return CostRatios{r.replay->total_s / c.total_s, r.replay->latency->p99 / c.latency.p99};
}

// "- what: n of m rows; misses: a (figures), b (figures)".
void tallyLine(std::ostream& out, const std::string& what, int met, int of,
               const std::vector<std::string>& misses) {
  out << "- " << what << ": " << met << " of " << of << " rows";
  for (size_t k = 0; k < misses.size(); ++k) out << (k == 0 ? "; misses: " : ", ") << misses[k];
  out << "\n";
}

std::string qualityFigures(const RobustFigures& f) {
  if (!f.ok) return "failed";
  return "F/F* " + fmt("%.4g", f.F_ratio) + ", P " + fmt("%.3f", f.score.precision) + ", R " +
         fmt("%.3f", f.score.recall);
}

}  // namespace

bool solved(const RobustFigures& f) {
  return f.ok && f.F_ratio <= 1.01 && f.score.precision >= 0.95 && f.score.recall >= 0.95;
}

std::string robustGoals(const std::vector<RobustRow>& rows) {
  std::ostringstream out;
  for (const bool replay : {true, false}) {
    int met = 0, of = 0;
    std::vector<std::string> misses;
    for (const RobustRow& r : rows) {
      if (!r.error.empty() || !qualityGoalCovers(r)) continue;
      const RobustFigures* f = replay ? (r.replay ? &*r.replay : nullptr) : &r.batch;
      if (f == nullptr) continue;
      ++of;
      if (solved(*f)) {
        ++met;
      } else {
        misses.push_back(r.c.name + " (" + qualityFigures(*f) + ")");
      }
    }
    if (of > 0)
      tallyLine(out,
                std::string("Issue 14's quality goal (F_clean/F* ≤ 1.01, P and R ≥ 0.95; 10% and "
                            "50%, 90% random in 2D), ") +
                    (replay ? "the replay" : "the batch"),
                met, of, misses);
  }
  int met = 0, of = 0;
  std::vector<std::string> misses;
  for (const RobustRow& r : rows) {
    if (!r.error.empty()) continue;
    const std::optional<CostRatios> c = costRatios(r);
    if (!c) continue;
    ++of;
    if (c->total <= 2 && c->p99 <= 3) {
      ++met;
    } else {
      misses.push_back(r.c.name + " (" + fmt("%.2f", c->total) + "×, p99 " + fmt("%.2f", c->p99) +
                       "×)");
    }
  }
  if (of > 0)
    tallyLine(out, "Issue 14's cost goal (the replay's total ≤ 2× and p99 ≤ 3× the clean replay's)",
              met, of, misses);
  return out.str();
}

std::string robustMarkdown(const std::vector<RobustRow>& rows) {
  bool replay = false;
  for (const RobustRow& r : rows) replay |= r.replay.has_value() || r.clean_replay.has_value();
  std::ostringstream md;
  md << "| file | dim | false / loops | F_clean / F* | ATE | precision | recall | rejected | GNC "
        "steps | total s | GTSAM GNC: F/F* · ATE · P · R · s | riSAM: F/F* · ATE · P · R · s | "
        "iSAM2 + Cauchy: F/F* · ATE · P · R · s |";
  if (replay)
    md << " replay: F/F* · ATE · P · R | replay s | p50 ms | p99 ms | max ms | clean replay s | "
          "total/clean | p99/clean |";
  md << "\n|---|---|---|---|---|---|---|---|---|---|---|---|---|";
  if (replay) md << "---|---|---|---|---|---|---|---|";
  md << "\n";
  for (const RobustRow& r : rows) {
    md << "| " << r.c.name << " | ";
    if (!r.error.empty()) {
      md << "— | — | failed | — | — | — | — | — | — | " << anchorCell(r.gnc) << " | "
         << anchorCell(r.risam) << " | " << anchorCell(r.isam2_cauchy) << " |";
      if (replay) md << " — | — | — | — | — | — | — | — |";
      md << "\n";
      continue;
    }
    const RobustFigures& b = r.batch;
    md << r.dim << " | " << r.false_edges << " / " << r.loop_closures << " | ";
    if (b.ok) {
      md << orDash(b.F_ratio, "%.6g") << " | " << orDash(b.ate, "%.3g") << " | "
         << orDash(b.score.precision, "%.3f") << " | " << orDash(b.score.recall, "%.3f") << " | "
         << b.score.rejected << " | " << b.steps << " | " << fmt("%.3g", b.total_s) << " | ";
    } else {
      md << "failed | — | — | — | — | — | — | ";
    }
    md << anchorCell(r.gnc) << " | " << anchorCell(r.risam) << " | " << anchorCell(r.isam2_cauchy)
       << " |";
    if (replay) {
      const bool has = r.replay.has_value();
      const RobustFigures* p = has ? &*r.replay : nullptr;
      const bool timed = p && p->ok;
      const bool lat = timed && p->latency.has_value();
      md << " " << (has ? quality(*p) : "—") << " | " << (timed ? fmt("%.3g", p->total_s) : "—")
         << " | " << (lat ? fmt("%.3f", p->latency->p50) : "—") << " | "
         << (lat ? fmt("%.3f", p->latency->p99) : "—") << " | "
         << (lat ? fmt("%.2f", p->latency->max) : "—") << " | ";
      const bool clean = r.clean_replay.has_value() && std::isfinite(r.clean_replay->total_s);
      md << (clean ? fmt("%.3g", r.clean_replay->total_s) : "—") << " | "
         << (clean && timed && r.clean_replay->total_s > 0
                 ? fmt("%.2f", p->total_s / r.clean_replay->total_s)
                 : "—")
         << " | "
         << (clean && lat && r.clean_replay->latency.p99 > 0
                 ? fmt("%.2f", p->latency->p99 / r.clean_replay->latency.p99)
                 : "—")
         << " |";
    }
    md << "\n";
  }

  std::ostringstream notes;
  std::set<std::string> bases;
  for (const RobustRow& r : rows) {
    if (!r.error.empty() || !bases.insert(r.c.base).second) continue;
    notes << "- " << r.c.base << ": clean optimum by " << r.reference_method
          << (r.reference_method == "lm" ? " from the file's vertices"
                                         : " (chordal start, LM polish)")
          << ", F " << fmt("%.10g", r.F_reference) << " (F* "
          << (std::isfinite(r.F_star)
                  ? fmt("%.10g", r.F_star) + ", ratio " + fmt("%.6g", r.F_reference / r.F_star)
                  : std::string("unknown"))
          << ")\n";
  }
  for (const RobustRow& r : rows) {
    if (!r.error.empty()) notes << "- " << r.c.name << ": " << r.error << "\n";
    if (r.error.empty() && !r.batch.ok)
      notes << "- " << r.c.name << ", batch: " << r.batch.error << "\n";
    if (r.replay && !r.replay->ok)
      notes << "- " << r.c.name << ", replay: " << r.replay->error << "\n";
  }
  // Each reference tool the table has a column for but no row of: said, not left blank.
  const std::pair<std::optional<RobustAnchor> RobustRow::*, const char*> tools[] = {
      {&RobustRow::gnc, "gnc (GTSAM GNC)"},
      {&RobustRow::risam, "risam (riSAM)"},
      {&RobustRow::isam2_cauchy, "isam2_cauchy (iSAM2 + Cauchy)"}};
  for (const auto& [member, tool] : tools) {
    bool shared = false, any = false;
    for (const RobustRow& r : rows) {
      if (r.c.generated) continue;
      shared = true;
      any |= (r.*member).has_value();
    }
    if (shared && !any)
      notes << "- reference/robust-anchors.tsv holds no row of tool " << tool
            << " for these files: its column is empty\n";
  }
  notes << robustGoals(rows);
  if (!notes.str().empty()) md << "\n" << notes.str();
  return md.str();
}

template std::vector<RobustCase> plantRobustCases(PoseGraph2, const RobustCase&,
                                                  const std::vector<double>&,
                                                  const std::vector<sim::OutlierPolicy>&,
                                                  std::uint64_t, const std::string&,
                                                  const std::string&);
template std::vector<RobustCase> plantRobustCases(PoseGraph3, const RobustCase&,
                                                  const std::vector<double>&,
                                                  const std::vector<sim::OutlierPolicy>&,
                                                  std::uint64_t, const std::string&,
                                                  const std::string&);
template RobustEstimate<SE2> robustBatch(const PoseGraph2&, const RobustBatchSettings&);
template RobustEstimate<SE3> robustBatch(const PoseGraph3&, const RobustBatchSettings&);
template CleanReference<SE2> cleanReference(PoseGraph2, double);
template CleanReference<SE3> cleanReference(PoseGraph3, double);
template RobustFigures judgeEstimate(const PoseGraph2&, const RobustEstimate<SE2>&,
                                     const std::vector<LabelPair>&, const CleanReference<SE2>&);
template RobustFigures judgeEstimate(const PoseGraph3&, const RobustEstimate<SE3>&,
                                     const std::vector<LabelPair>&, const CleanReference<SE3>&);

}  // namespace arbor::bench
