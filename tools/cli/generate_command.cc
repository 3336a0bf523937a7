// arbor generate KIND: write a synthetic pose graph (deterministic by seed) as g2o.
#include <iostream>

#include "io/pose_graph_file.h"
#include "tools/cli/cli_common.h"
#include "tools/cli/commands.h"
#include "tools/generator/graph_generator.h"

namespace arbor::cli {

namespace po = boost::program_options;

int generateCommand(const std::vector<std::string>& args) {
  std::string kind, output, truth_output;
  int poses = 0, rings = 0, per_ring = 0, size = 0, grid = 0;
  std::uint64_t seed = 1;
  double sigma_t = 0.05, sigma_r = 0.01, closure_probability = -1;
  po::options_description options("arbor generate manhattan|sphere|grid [options]");
  options.add_options()("help,h", "show this help")("kind", po::value(&kind)->required(),
                                                    "manhattan | sphere | grid")(
      "output,o", po::value(&output)->required(), "g2o file to write")(
      "truth", po::value(&truth_output), "also write the ground truth poses as g2o")(
      "seed", po::value(&seed)->default_value(1), "random seed")(
      "poses", po::value(&poses), "number of poses (manhattan: 3500, grid: 1000)")(
      "grid", po::value(&grid), "manhattan: world size in cells (10)")(
      "size", po::value(&size), "grid: lattice size per axis (6)")(
      "rings", po::value(&rings), "sphere: number of rings (20)")("per-ring", po::value(&per_ring),
                                                                  "sphere: poses per ring (50)")(
      "closure-probability", po::value(&closure_probability),
      "manhattan, grid: chance of a loop closure on a revisit (0.3 / 0.5)")(
      "sigma-t", po::value(&sigma_t)->default_value(0.05), "translation noise (m)")(
      "sigma-r", po::value(&sigma_r)->default_value(0.01), "rotation noise (rad)");
  po::positional_options_description positional;
  positional.add("kind", 1);
  if (helpRequested(args, options)) return 0;
  parseArguments(args, options, positional);
  if (!(sigma_t > 0) || !(sigma_r > 0)) throw UsageError("noise sigmas must be positive");
  if (closure_probability != -1 && !(closure_probability >= 0 && closure_probability <= 1))
    throw UsageError("--closure-probability must be in [0, 1]");
  const sim::NoiseModel noise{sigma_t, sigma_r};

  auto write = [&](const auto& simulation) {
    writeG2oFile(output, simulation.graph, simulation.graph.poses);
    if (!truth_output.empty()) writeG2oFile(truth_output, simulation.graph, simulation.truth);
    std::cout << "wrote " << output << ": " << simulation.graph.numPoses() << " poses, "
              << simulation.graph.numEdges() << " edges\n";
  };
  if (kind == "manhattan") {
    sim::ManhattanOptions o;
    o.seed = seed;
    o.noise = noise;
    if (poses) o.poses = poses;
    if (grid) o.grid = grid;
    if (closure_probability >= 0) o.closure_probability = closure_probability;
    if (o.poses < 2 || o.grid < 2) throw UsageError("--poses and --grid must be at least 2");
    write(sim::manhattanWorld(o));
  } else if (kind == "sphere") {
    sim::SphereOptions o;
    o.seed = seed;
    o.noise = noise;
    if (rings) o.rings = rings;
    if (per_ring) o.poses_per_ring = per_ring;
    if (o.rings < 1 || o.poses_per_ring < 2) throw UsageError("--rings >= 1 and --per-ring >= 2");
    write(sim::sphereWorld(o));
  } else if (kind == "grid") {
    sim::GridOptions o;
    o.seed = seed;
    o.noise = noise;
    if (poses) o.poses = poses;
    if (size) o.size = size;
    if (closure_probability >= 0) o.closure_probability = closure_probability;
    if (o.poses < 2 || o.size < 2) throw UsageError("--poses and --size must be at least 2");
    write(sim::gridWorld(o));
  } else {
    throw UsageError("unknown kind '" + kind + "' (manhattan, sphere or grid)");
  }
  return 0;
}

}  // namespace arbor::cli
