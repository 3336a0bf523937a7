#include "arbor_slam/tools/bench/paper_runner.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "arbor_slam/core/initialization.h"
#include "arbor_slam/tools/bench/format.h"
#include "arbor_slam/tools/refine/batch_solvers.h"

namespace arbor::bench {
namespace {

namespace fs = std::filesystem;

// One row of refine::batchSolvers() as `arbor batch --solver NAME` runs it: gn, lm and dogleg
// from `start`, rtr from its own chordal relaxation.
template <class G>
SolverRun runSolver(refine::BatchSolver solver, const PoseGraph<G>& graph,
                    const std::vector<G>& start, const PaperSettings& settings,
                    std::vector<G>* poses) {
  refine::BatchSolveSettings solve_settings;
  solve_settings.max_iterations = settings.max_iterations;
  solve_settings.relative_tolerance = settings.relative_tolerance;
  solve_settings.rtr.gradient_tolerance = settings.rtr_gradient_tolerance;
  if (!refine::info(solver).own_start) *poses = start;
  const refine::BatchSolve s = refine::runBatchSolver(solver, graph, poses, solve_settings);
  SolverRun run;
  run.solver = refine::toString(solver);
  run.time_s = s.time_s;
  run.iterations = s.iterations;
  if (s.rtr) {
    run.termination = s.rtr->certified ? "certified" : "converged";
    if (!s.rtr->certified) {
      run.note = !s.message.empty()         ? s.message
                 : s.rtr->relaxation_solved ? "relaxation not exact"
                                            : "not certified";
    }
  } else {
    run.termination = s.diverged ? "failed" : s.termination;
    if (s.diverged) run.note = s.message;
  }
  return run;
}

const std::function<SolverRun(const PoseGraph2&, std::vector<SE2>*)>& externalFor(
    const ExternalSolver& e, const PoseGraph2*) {
  return e.solve2;
}
const std::function<SolverRun(const PoseGraph3&, std::vector<SE3>*)>& externalFor(
    const ExternalSolver& e, const PoseGraph3*) {
  return e.solve3;
}

double relative(double F, double F_star) { return (F - F_star) / F_star; }

std::string shortTermination(const std::string& t) {
  if (t == "max_iterations") return "max it";
  return t;
}

// The run named `solver` in `report`, or nullptr.
const SolverRun* find(const DatasetReport& report, const std::string& solver) {
  for (const auto& r : report.runs) {
    if (r.solver == solver) return &r;
  }
  return nullptr;
}

}  // namespace

template <class G>
void writeEstimateCsv(const std::string& path, const std::vector<G>& poses) {
  std::ofstream csv(path);
  if (!csv) throw std::runtime_error("writeEstimateCsv: cannot write " + path);
  csv << (G::kDim == 2 ? "x,y\n" : "x,y,z\n");
  char buf[96];
  for (const G& pose : poses) {
    const auto& t = pose.translation();
    if constexpr (G::kDim == 2) {
      std::snprintf(buf, sizeof buf, "%.6g,%.6g\n", t.x(), t.y());
    } else {
      std::snprintf(buf, sizeof buf, "%.6g,%.6g,%.6g\n", t.x(), t.y(), t.z());
    }
    csv << buf;
  }
  if (!csv) throw std::runtime_error("writeEstimateCsv: error writing " + path);
}

template <class G>
DatasetReport runPaperBenchmark(const std::string& name, const PoseGraph<G>& graph,
                                const PaperSettings& settings,
                                const std::vector<ExternalSolver>& external) {
  DatasetReport report;
  report.name = name;
  report.dim = G::kDim;
  report.poses = graph.numPoses();
  report.edges = graph.numEdges();
  std::string estimate_dir;
  if (!settings.out_dir.empty()) {
    estimate_dir = (fs::path(settings.out_dir) / "estimates" / name).string();
    fs::create_directories(estimate_dir);
    fs::create_directories(fs::path(settings.out_dir) / "latency");
  }
  // Runs `solve` (which fills poses and the run's time, iterations, termination), scores the
  // estimate in our F and writes it; an exception becomes a failed run.
  auto record = [&](const std::string& solver, auto solve) {
    std::vector<G> poses;
    SolverRun run;
    try {
      run = solve(&poses);
      run.solver = solver;
      if (poses.size() != graph.poses.size()) {
        throw std::runtime_error("estimate has " + std::to_string(poses.size()) + " poses, not " +
                                 std::to_string(graph.poses.size()));
      }
      run.F = objective(graph, poses);
    } catch (const std::exception& e) {
      run = SolverRun{};
      run.solver = solver;
      run.termination = "failed";
      run.note = e.what();
      poses.clear();
    }
    if (!estimate_dir.empty() && !poses.empty()) {
      run.estimate_file = (fs::path(estimate_dir) / (solver + ".csv")).string();
      writeEstimateCsv(run.estimate_file, poses);
    }
    report.runs.push_back(run);
  };

  if (settings.replay) {
    record("replay", [&](std::vector<G>* poses) {
      cli::ReplaySettings replay;
      replay.batch = false;
      const cli::ReplayResult<G> r = cli::runReplay(graph, replay);
      *poses = r.poses;
      report.latency = r.latency;
      if (!settings.out_dir.empty()) {
        report.latency_file = (fs::path(settings.out_dir) / "latency" / (name + ".csv")).string();
        cli::writeLatencyCsv(report.latency_file, r.rows);
      }
      SolverRun run;
      run.time_s = r.total_s;
      run.iterations = static_cast<int>(r.rows.size());
      run.termination = r.rejected || r.pending ? "failed" : "complete";
      auto add = [&](int count, const char* what) {
        if (count) run.note += (run.note.empty() ? "" : ", ") + std::to_string(count) + what;
      };
      add(r.rejected, " edges rejected");
      add(r.pending, " edges pending");
      add(r.indeterminate, " cliques damped");
      return run;
    });
  }
  // The paper's libraries start from the file's estimate; we start every local solver from the
  // same breadth-first spanning tree (odometry stalls on MIT, see ../shared/NOTES.md).
  std::vector<G> start;
  try {
    start = spanningTreeInitialization(graph);
  } catch (const std::exception&) {
    start.clear();  // each solver below then fails with the message of its own attempt
  }
  auto from_start = [&](std::vector<G>* poses) {
    if (start.empty()) start = spanningTreeInitialization(graph);  // throws the reason
    *poses = start;
  };
  for (const refine::BatchSolverInfo& row : refine::batchSolvers()) {
    record(row.name, [&](std::vector<G>* poses) {
      if (!row.own_start) from_start(poses);
      return runSolver(row.solver, graph, start, settings, poses);
    });
  }
  for (const auto& e : external) {
    const auto& solve = externalFor(e, static_cast<const PoseGraph<G>*>(nullptr));
    if (!solve) continue;
    record(e.name, [&](std::vector<G>* poses) {
      from_start(poses);
      return solve(graph, poses);
    });
  }
  return report;
}

void writeResultsTsv(const std::string& path, const std::vector<DatasetReport>& reports) {
  std::ofstream out(path);
  if (!out) throw std::runtime_error("writeResultsTsv: cannot write " + path);
  out << "dataset\tdim\tposes\tedges\tsolver\ttime_s\tF\tF_star\tF_rel\titerations\ttermination"
         "\tnote\testimate\n";
  out.precision(10);
  for (const auto& d : reports) {
    for (const auto& r : d.runs) {
      out << d.name << '\t' << d.dim << '\t' << d.poses << '\t' << d.edges << '\t' << r.solver
          << '\t' << r.time_s << '\t' << r.F << '\t' << d.F_star << '\t' << relative(r.F, d.F_star)
          << '\t' << r.iterations << '\t' << r.termination << '\t' << r.note << '\t'
          << r.estimate_file << '\n';
    }
  }
  if (!out) throw std::runtime_error("writeResultsTsv: error writing " + path);
}

void writeResultsJson(const std::string& path, const std::vector<DatasetReport>& reports) {
  auto number = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); };
  nlohmann::json all = nlohmann::json::array();
  for (const auto& d : reports) {
    nlohmann::json runs = nlohmann::json::array();
    for (const auto& r : d.runs) {
      runs.push_back({{"solver", r.solver},
                      {"time_s", r.time_s},
                      {"F", number(r.F)},
                      {"F_rel", number(relative(r.F, d.F_star))},
                      {"iterations", r.iterations},
                      {"termination", r.termination},
                      {"note", r.note},
                      {"estimate", r.estimate_file}});
    }
    all.push_back({{"dataset", d.name},
                   {"note", d.note},
                   {"dim", d.dim},
                   {"poses", d.poses},
                   {"edges", d.edges},
                   {"F_star", number(d.F_star)},
                   {"latency_ms",
                    {{"p50", d.latency.p50},
                     {"p90", d.latency.p90},
                     {"p99", d.latency.p99},
                     {"max", d.latency.max}}},
                   {"latency_csv", d.latency_file},
                   {"runs", runs}});
  }
  std::ofstream out(path);
  if (!out) throw std::runtime_error("writeResultsJson: cannot write " + path);
  out << all.dump(1) << "\n";
  if (!out) throw std::runtime_error("writeResultsJson: error writing " + path);
}

std::string paperMarkdown(const std::vector<DatasetReport>& reports, const std::string& baseline) {
  // Solver columns in order of first appearance.
  std::vector<std::string> solvers;
  std::set<std::string> seen;
  for (const auto& d : reports) {
    for (const auto& r : d.runs) {
      if (seen.insert(r.solver).second) solvers.push_back(r.solver);
    }
  }
  // `first` holds the leading column names, "a | b".
  auto header = [&](std::ostringstream& md, const std::string& first) {
    md << "| " << first << " |";
    for (const auto& s : solvers) md << " " << s << " |";
    md << "\n|---|";
    for (char c : first) md << (c == '|' ? "---|" : "");
    for (size_t k = 0; k < solvers.size(); ++k) md << "---|";
    md << "\n";
  };
  auto label = [](const DatasetReport& d) { return d.name + d.note; };
  std::ostringstream md;

  md << "### Time, F and termination per solver (Table II's shape)\n\n"
        "Each cell: solve time in s · F = Σ eᵀΩe at the estimate · termination.\n\n";
  header(md, "dataset");
  for (const auto& d : reports) {
    md << "| " << label(d) << " |";
    for (const auto& s : solvers) {
      const SolverRun* r = find(d, s);
      if (!r) {
        md << " — |";
      } else if (!std::isfinite(r->F)) {
        md << " failed |";
      } else {
        md << " " << fmt("%.3f", r->time_s) << " s · " << fmt("%.7g", r->F) << " · "
           << shortTermination(r->termination) << " |";
      }
    }
    md << "\n";
  }

  md << "\n### F against F* (reference/optimum.tsv) and iterations\n\n"
        "Each cell: (F − F*)/F* · iterations (replay: updates; rtr: trust-region "
        "iterations).\n\n";
  header(md, "dataset | F*");
  for (const auto& d : reports) {
    md << "| " << label(d) << " | "
       << (std::isfinite(d.F_star) ? fmt("%.7g", d.F_star) : std::string("—")) << " |";
    for (const auto& s : solvers) {
      const SolverRun* r = find(d, s);
      if (!r || !std::isfinite(r->F)) {
        md << " — |";
      } else {
        md << " "
           << (std::isfinite(d.F_star) ? fmt("%+.4f%%", 100.0 * relative(r->F, d.F_star))
                                       : std::string("—"))
           << " · " << r->iterations << " |";
      }
    }
    md << "\n";
  }

  if (seen.count(baseline)) {
    md << "\n### Time ratio to " << baseline << " (solver time / " << baseline
       << " time; < 1 is faster)\n\n";
    header(md, "dataset");
    for (const auto& d : reports) {
      const SolverRun* b = find(d, baseline);
      md << "| " << label(d) << " |";
      for (const auto& s : solvers) {
        const SolverRun* r = find(d, s);
        if (!r || !b || !std::isfinite(r->F) || !std::isfinite(b->F) || b->time_s <= 0) {
          md << " — |";
        } else {
          md << " " << fmt("%.2f", r->time_s / b->time_s) << " |";
        }
      }
      md << "\n";
    }
  }

  bool any_replay = false;
  for (const auto& d : reports) any_replay |= find(d, "replay") != nullptr;
  if (any_replay) {
    md << "\n### Incremental replay: per-update latency\n\n"
          "| dataset | edges | updates | total s | p50 ms | p90 ms | p99 ms | max ms | F | vs F* "
          "|\n|---|---|---|---|---|---|---|---|---|---|\n";
    for (const auto& d : reports) {
      const SolverRun* r = find(d, "replay");
      if (!r) continue;
      md << "| " << label(d) << " | " << d.edges << " | " << r->iterations << " | "
         << fmt("%.3f", r->time_s) << " | " << fmt("%.3f", d.latency.p50) << " | "
         << fmt("%.3f", d.latency.p90) << " | " << fmt("%.3f", d.latency.p99) << " | "
         << fmt("%.2f", d.latency.max) << " | " << fmt("%.7g", r->F) << " | "
         << (std::isfinite(d.F_star) && std::isfinite(r->F)
                 ? fmt("%+.3f%%", 100.0 * relative(r->F, d.F_star))
                 : std::string("—"))
         << " |\n";
    }
  }

  // Failures and notes, so that a "failed" cell has its reason next to the table.
  std::ostringstream notes;
  for (const auto& d : reports) {
    for (const auto& r : d.runs) {
      if (!r.note.empty()) notes << "- " << d.name << ", " << r.solver << ": " << r.note << "\n";
    }
  }
  if (!notes.str().empty()) md << "\nNotes:\n\n" << notes.str();
  return md.str();
}

template DatasetReport runPaperBenchmark(const std::string&, const PoseGraph2&,
                                         const PaperSettings&, const std::vector<ExternalSolver>&);
template DatasetReport runPaperBenchmark(const std::string&, const PoseGraph3&,
                                         const PaperSettings&, const std::vector<ExternalSolver>&);
template void writeEstimateCsv(const std::string&, const std::vector<SE2>&);
template void writeEstimateCsv(const std::string&, const std::vector<SE3>&);

}  // namespace arbor::bench
