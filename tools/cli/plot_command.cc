// arbor plot ESTIMATE [REFERENCE] [-o OUT.png]: an estimate's trajectory drawn as a PNG and, with
// a reference, its ATE and RPE by evo's definitions (tools/cli/trajectory_errors.h). The metrics
// are computed here; the drawing is tools/plots/plot_trajectory.py's (matplotlib), run with
// /usr/bin/python3 (else the python3 on PATH).
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "arbor_slam/io/trajectory_reader.h"
#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/commands.h"
#include "arbor_slam/tools/cli/output_files.h"
#include "arbor_slam/tools/cli/plot_command.h"
#include "arbor_slam/tools/cli/trajectory_errors.h"

namespace arbor::cli {
namespace {

namespace fs = std::filesystem;
namespace po = boost::program_options;

/// The drawing script: $ARBOR_PLOT_SCRIPT, else beside this executable in the build tree
/// (BUILD/tools/plots/) or in an installed prefix (PREFIX/share/arbor/).
std::string plotScript() {
  if (const char* env = std::getenv("ARBOR_PLOT_SCRIPT")) {
    if (!fs::is_regular_file(env))
      throw std::runtime_error(std::string("ARBOR_PLOT_SCRIPT=") + env + ": no such file");
    return env;
  }
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  const fs::path dir = ec ? fs::path(".") : exe.parent_path();
  for (const fs::path& candidate : {dir / "plots" / "plot_trajectory.py",
                                    dir.parent_path() / "share" / "arbor" / "plot_trajectory.py"})
    if (fs::is_regular_file(candidate)) return candidate.string();
  throw std::runtime_error("no plot_trajectory.py beside " + exe.string() +
                           " (tools/plots/; or set ARBOR_PLOT_SCRIPT)");
}

/// Runs `python3 script args…`, waiting; throws naming the exit status when it fails.
void runPython(const std::string& script, const std::vector<std::string>& args) {
  const std::string python = fs::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3";
  std::vector<std::string> argv = {python, script};
  argv.insert(argv.end(), args.begin(), args.end());
  std::vector<char*> c_argv;
  for (std::string& a : argv) c_argv.push_back(a.data());
  c_argv.push_back(nullptr);
  std::cout.flush();
  const pid_t pid = fork();
  if (pid < 0) throw std::runtime_error(std::string("fork: ") + std::strerror(errno));
  if (pid == 0) {
    execvp(c_argv[0], c_argv.data());
    std::cerr << "arbor plot: cannot run " << python << ": " << std::strerror(errno) << "\n";
    _exit(127);
  }
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
    throw std::runtime_error(python + " " + script + " failed (status " +
                             std::to_string(WIFEXITED(status) ? WEXITSTATUS(status) : -1) +
                             "; it needs matplotlib: python3-matplotlib)");
}

std::string number(double v) {
  std::ostringstream s;
  s.precision(6);
  s << v;
  return s.str();
}

using P = PlotOptions;

const char* const kPlotSection = "Plot";

OptionTable<P> makePlotTable() {
  return {
      numberOption<P>(
          "max-time-diff", Tier::kCommon, kPlotSection, "S",
          "poses of the two associate when their times (TUM stamps, g2o ids, KITTI line numbers) "
          "differ by at most this, as evo's t_max_diff",
          [](auto& o) -> auto& { return o.max_time_diff; },
          Condition{">= 0", [](double x) { return x >= 0; }}),
      switchOption<P>(
          "json", Tier::kCommon, kPlotSection, "print one JSON object",
          [](auto& o) -> auto& { return o.json; }, true),
  };
}

FlagSet plotFlagSet(P* o) {
  FlagSet flags(
      "arbor plot ESTIMATE [REFERENCE] [options]   (TUM, KITTI or g2o/TORO files; with "
      "REFERENCE, the ground truth: ATE and RPE by evo's definitions, docs/files.md)",
      {"arbor plot estimate.tum", "arbor plot estimate.g2o truth.tum -o compared.png --json"});
  flags.positional("estimate", po::value(&o->estimate)->required());
  flags.positional("reference", po::value(&o->reference));
  flags.add(Tier::kCommon, kPlotSection)("output,o", po::value(&o->output)->value_name("OUT.png"),
                                         "the PNG (default: ESTIMATE with .png for its extension)");
  flags.add(plotOptionTable());
  return flags;
}

}  // namespace

const OptionTable<PlotOptions>& plotOptionTable() {
  static const OptionTable<PlotOptions> table = makePlotTable();
  return table;
}

std::vector<FlagInfo> plotFlags() {
  P o;
  return plotFlagSet(&o).flags();
}

std::optional<PlotOptions> parsePlotCommandLine(const std::vector<std::string>& args) {
  P o;
  const FlagSet flags = plotFlagSet(&o);
  const std::optional<po::variables_map> parsed = flags.parse(args);
  if (!parsed) return std::nullopt;
  readOptions(plotOptionTable(), *parsed, &o);
  if (o.output.empty()) o.output = fs::path(o.estimate).replace_extension(".png").string();
  if (o.output == o.estimate || o.output == o.reference)
    throw UsageError("-o " + o.output + " would overwrite an input");
  return o;
}

int plotCommand(const std::vector<std::string>& args) {
  const std::optional<PlotOptions> options = parsePlotCommandLine(args);
  if (!options) return 0;
  const std::string &estimate_file = options->estimate, &reference_file = options->reference,
                    &output = options->output;
  const double max_diff = options->max_time_diff;
  const bool json = options->json;
  requireWritable("--output", output);

  const Trajectory estimate = readTrajectoryFile(estimate_file);
  if (estimate.poses.empty()) throw FileError(estimate_file + ": no poses");
  nlohmann::json j = {{"estimate", {{"file", estimate_file}, {"poses", estimate.poses.size()}}}};
  std::ostringstream text;
  text << "estimate   " << estimate_file << " (" << estimate.poses.size() << " poses)\n";
  SE3 alignment;
  Trajectory reference;
  std::string title = fs::path(estimate_file).filename().string();
  if (!reference_file.empty()) {
    reference = readTrajectoryFile(reference_file);
    TrajectoryErrors e;
    try {
      e = trajectoryErrors(estimate, reference, max_diff);
    } catch (const std::invalid_argument& error) {
      throw std::runtime_error(estimate_file + " against " + reference_file + ": " + error.what());
    }
    alignment = e.alignment;
    j["reference"] = {
        {"file", reference_file}, {"poses", reference.poses.size()}, {"associated", e.associated}};
    j["ate"] = {{"rmse", e.ate_rmse}, {"mean", e.ate_mean}, {"max", e.ate_max}};
    j["rpe"] = {{"rmse", e.rpe_rmse}, {"pairs", e.rpe_pairs}};
    text << "reference  " << reference_file << " (" << reference.poses.size() << " poses, "
         << e.associated << " associated)\n"
         << "ATE        rmse " << number(e.ate_rmse) << "  mean " << number(e.ate_mean) << "  max "
         << number(e.ate_max) << "  (after a rigid SE(3) alignment, no scale)\n"
         << "RPE        rmse " << number(e.rpe_rmse) << "  (translation, " << e.rpe_pairs
         << " pairs one step apart)\n";
    title += " vs " + fs::path(reference_file).filename().string() + "\nATE " + number(e.ate_rmse) +
             " (SE(3)-aligned)   RPE " + number(e.rpe_rmse) + " (1 step)";
  }

  const fs::path csv = fs::temp_directory_path() /
                       ("arbor_plot_" + std::to_string(::getpid()) + "_trajectories.csv");
  {
    std::ofstream out(csv);
    if (!out) throw std::runtime_error(csv.string() + ": cannot open for writing");
    out.precision(17);
    out << "series,x,y\n";
    for (const SE3& x : reference.poses)
      out << "reference," << x.translation().x() << "," << x.translation().y() << "\n";
    for (const SE3& x : estimate.poses) {
      const Eigen::Vector3d p = alignment.act(x.translation());
      out << "estimate," << p.x() << "," << p.y() << "\n";
    }
    if (!out) throw std::runtime_error(csv.string() + ": write failed");
  }
  try {
    runPython(plotScript(), {csv.string(), output, title});
  } catch (...) {
    fs::remove(csv);
    throw;
  }
  fs::remove(csv);
  j["plot"] = output;
  text << "plot       " << output << "\n";
  if (json)
    std::cout << j.dump() << "\n";
  else
    std::cout << text.str();
  return 0;
}

}  // namespace arbor::cli
