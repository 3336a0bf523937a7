#include "arbor_slam/tools/bench/family_bench.h"

#include <cmath>
#include <filesystem>
#include <map>
#include <set>
#include <sstream>
#include <stdexcept>
#include <tuple>

#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tools/bench/format.h"
#include "arbor_slam/tools/bench/world_families.h"

namespace arbor::bench {
namespace {

namespace fs = std::filesystem;

template <class G>
std::vector<RobustCase> plantWorld(const sim::Simulation<G>& world, const RobustCase& like,
                                   const FamilyPlan& plan, std::uint64_t seed,
                                   const std::string& out_dir) {
  writeG2oFile(like.base_file, world.graph, world.graph.poses);
  return plantRobustCases(world.graph, like, plan.fractions, plan.policies, seed, out_dir, "");
}

// "F/F* · P · R" of a judged estimate, "failed" or "—".
std::string figures(const std::optional<RobustFigures>& f) {
  if (!f) return "—";
  if (!f->ok) return "failed";
  auto num = [](double v, const char* format) {
    return std::isfinite(v) ? fmt(format, v) : std::string("—");
  };
  return num(f->F_ratio, "%.4f") + " · " + num(f->score.precision, "%.3f") + " · " +
         num(f->score.recall, "%.3f");
}

std::string mark(const std::optional<RobustFigures>& f) {
  return f ? (solved(*f) ? "yes" : "no") : "—";
}

}  // namespace

std::vector<RobustCase> generateFamilyCases(const FamilyPlan& plan, const std::string& out_dir) {
  std::vector<RobustCase> cases;
  for (const std::string& name : plan.families) {
    const std::optional<WorldFamily> family = worldFamily(name);
    if (!family) {
      std::string known;
      for (const std::string& n : worldFamilyNames()) known += (known.empty() ? "" : ", ") + n;
      throw std::invalid_argument("--family: unknown family '" + name + "' (" + known + ")");
    }
    for (const int dim : plan.dims) {
      if (dim != 2 && dim != 3)
        throw std::invalid_argument("--dims: " + std::to_string(dim) + " is not 2 or 3");
      for (const std::uint64_t seed : plan.seeds) {
        const sim::RoadOptions options = familyWorldOptions(*family, seed);
        RobustCase like;
        like.base = familyWorldName(*family, dim, seed);
        like.base_file = (fs::path(out_dir) / (like.base + ".g2o")).string();
        like.generated = true;
        like.family = family->name;
        like.information_scale = options.noise.information_scale;
        const std::vector<RobustCase> planted =
            dim == 2 ? plantWorld(sim::roadWorld2(options), like, plan, seed, out_dir)
                     : plantWorld(sim::roadWorld3(options), like, plan, seed, out_dir);
        cases.insert(cases.end(), planted.begin(), planted.end());
      }
    }
  }
  return cases;
}

bool familyGoalCovers(int dim, double fraction) {
  return fraction <= 0.5 + 1e-9 || (dim == 2 && fraction <= 0.9 + 1e-9);
}

std::string familyMarkdown(const std::vector<RobustRow>& rows) {
  std::ostringstream md;
  md << "| case | X | loops | false | F* | replay: F/F* · P · R | replay solved | replay s | "
        "batch: F/F* · P · R | batch solved | batch s |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|\n";
  // (family, dim, fraction) → cases, replay solved, batch solved
  std::map<std::tuple<std::string, int, double>, std::tuple<int, int, int>> cells;
  std::vector<std::string> errors;
  for (const RobustRow& r : rows) {
    if (!r.error.empty()) {
      errors.push_back(r.c.name + ": " + r.error);
      md << "| " << r.c.name << " | failed: " << r.error << " | | | | | | | | | |\n";
      continue;
    }
    const std::optional<RobustFigures> batch = r.batch;  // as the replay's, for figures()
    md << "| " << r.c.name << " | " << fmt("%.3g", r.c.information_scale) << " | "
       << r.loop_closures << " | " << r.false_edges << " | " << fmt("%.6g", r.F_star) << " | "
       << figures(r.replay) << " | " << mark(r.replay) << " | "
       << (r.replay && r.replay->ok ? fmt("%.2f", r.replay->total_s) : "—") << " | "
       << figures(batch) << " | " << mark(batch) << " | "
       << (r.batch.ok ? fmt("%.2f", r.batch.total_s) : "—") << " |\n";
    auto& [n, replay, batch_solved] = cells[{r.c.family, r.dim, r.c.fraction}];
    ++n;
    replay += r.replay && solved(*r.replay);
    batch_solved += solved(r.batch);
  }
  md << "\n| family | dim | false closures | cases | replay solved | batch solved | goal |\n"
        "|---|---|---|---|---|---|---|\n";
  std::map<std::string, std::tuple<int, int, int>> covered;  // family → cases, replay, batch
  for (const auto& [key, counts] : cells) {
    const auto& [family, dim, fraction] = key;
    const auto& [n, replay, batch] = counts;
    const bool goal = familyGoalCovers(dim, fraction);
    md << "| " << family << " | " << dim << "D | " << fmt("%g", 100 * fraction) << "% | " << n
       << " | " << replay << " | " << batch << " | " << (goal ? "yes" : "no") << " |\n";
    if (goal) {
      auto& [cn, cr, cb] = covered[family];
      cn += n;
      cr += replay;
      cb += batch;
    }
  }
  md << "\n";
  std::set<std::string> worlds;
  for (const RobustRow& r : rows) {
    if (!r.error.empty() || !worlds.insert(r.c.base).second) continue;
    const std::optional<WorldFamily> family = worldFamily(r.c.family);
    md << "- " << r.c.base << ": X " << fmt("%.3g", r.c.information_scale) << ", " << r.poses
       << " poses, " << r.loop_closures << " loop closures ("
       << fmt("%.1f", 100.0 * r.loop_closures / (r.edges - r.false_edges))
       << "% of the edges), their χ² at the clean optimum: median "
       << fmt("%.3g", r.closure_chi2_median) << ", largest " << fmt("%.3g", r.closure_chi2_max)
       << "; clean optimum by " << r.reference_method << "; `arbor generate "
       << (family ? family->kind : r.c.family) << " --dim " << r.dim << " --seed "
       << r.c.base.substr(r.c.base.rfind("-s") + 2) << " --information-scale "
       << fmt("%.3g", r.c.information_scale) << "`\n";
  }
  for (const auto& [family, counts] : covered) {
    const auto& [n, replay, batch] = counts;
    md << "- " << family << ": the replay solves " << replay << " and the batch " << batch
       << " of the " << n << " cases the goal covers\n";
  }
  for (const std::string& e : errors) md << "- " << e << "\n";
  return md.str();
}

}  // namespace arbor::bench
