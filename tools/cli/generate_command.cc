// arbor generate KIND: write a synthetic pose graph (deterministic by seed) as g2o (manhattan,
// sphere, grid: graph_generator.h; vehicle, small-loop: road_world.h), optionally
// with false loop closures appended (tools/generator/false_closures.h) and their labels;
// `arbor generate outliers --input FILE` appends them to an existing graph.
#include <cmath>
#include <filesystem>
#include <iostream>
#include <sstream>
#include <stdexcept>

#include "arbor_slam/core/initialization.h"
#include "arbor_slam/io/labels_file.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/commands.h"
#include "arbor_slam/tools/generator/false_closures.h"
#include "arbor_slam/tools/generator/graph_generator.h"
#include "arbor_slam/tools/generator/road_world.h"

namespace arbor::cli {
namespace {

namespace po = boost::program_options;

// What --outliers asked for, and where the labels go.
struct OutlierRequest {
  bool on = false;
  sim::OutlierOptions options;
  std::string labels;  ///< NAME.labels beside NAME.g2o unless --labels says otherwise
};

// Appends the requested false closures to `graph` (when asked), writes the labels, and returns
// the words the summary line ends with.
template <class G>
std::string plantOutliers(const OutlierRequest& request, const std::string& input,
                          PoseGraph<G>* graph) {
  if (!request.on) return "";
  sim::FalseClosures<G> planted;
  try {
    planted = sim::addFalseClosures(*graph, request.options);
  } catch (const std::invalid_argument& e) {
    throw UsageError(input + ": " + e.what());
  }
  std::vector<LabelPair> labels;
  for (const auto& [i, j] : planted.pairs) labels.emplace_back(graph->ids[i], graph->ids[j]);
  const int loop_closures = sim::countLoopClosures(*graph);
  *graph = std::move(planted.graph);
  writeLabelsFile(request.labels, labels);
  std::ostringstream os;
  os << "; " << labels.size() << " false loop closures (" << toString(request.options.policy)
     << ", " << request.options.fraction << " of " << loop_closures << " loop closures, seed "
     << request.options.seed << ") appended, listed in " << request.labels;
  return os.str();
}

template <class G>
void printWritten(const std::string& output, const PoseGraph<G>& graph, const std::string& tail) {
  std::cout << "wrote " << output << ": " << graph.numPoses() << " poses, " << graph.numEdges()
            << " edges" << tail << "\n";
}

}  // namespace

int generateCommand(const std::vector<std::string>& args) {
  std::string kind, output, truth_output, input, policy = "random", labels, information = "refuse";
  int poses = 0, rings = 0, per_ring = 0, size = 0, grid = 0, dim = 2;
  std::uint64_t seed = 1;
  double sigma_t = 0.05, sigma_r = 0.01, closure_probability = -1, fraction = 0,
         information_scale = 1, closure_sigma_factor = 1, tail_fraction = 0, tail_factor = 1;
  po::options_description options(
      "arbor generate manhattan|sphere|grid|vehicle|small-loop [options]\n"
      "arbor generate outliers --input FILE -o OUT.g2o --outliers FRACTION [options]");
  options.add_options()("help,h", "show this help")(
      "kind", po::value(&kind)->required(),
      "manhattan | sphere | grid | vehicle | small-loop | outliers")(
      "output,o", po::value(&output)->required(), "g2o file to write")(
      "truth", po::value(&truth_output), "also write the ground truth poses as g2o")(
      "seed", po::value(&seed)->default_value(1),
      "random seed (of the graph and of its false loop closures)")(
      "poses", po::value(&poses),
      "number of poses (manhattan: 3500, grid: 1000, vehicle: 3000, small-loop: 1000)")(
      "dim", po::value(&dim)->default_value(2),
      "vehicle, small-loop: 2 (SE2) or 3 (SE3, the road over gentle hills: height and pitch "
      "change)")("grid", po::value(&grid), "manhattan: world size in cells (10)")(
      "size", po::value(&size), "grid: lattice size per axis (6)")(
      "rings", po::value(&rings), "sphere: number of rings (20)")("per-ring", po::value(&per_ring),
                                                                  "sphere: poses per ring (50)")(
      "closure-probability", po::value(&closure_probability),
      "manhattan, grid, vehicle, small-loop: chance of a loop closure on a revisit (0.3 / 0.5 / "
      "0.8 / 0.6)")("sigma-t", po::value(&sigma_t)->default_value(0.05),
                    "translation noise (m; vehicle, small-loop: 0.02)")(
      "sigma-r", po::value(&sigma_r)->default_value(0.01),
      "rotation noise (rad; vehicle, small-loop: 0.002)")(
      "closure-sigma-factor", po::value(&closure_sigma_factor),
      "draw the loop closures (|i - j| > 1) with both sigmas times F, their Ω from that noise "
      "(1; vehicle, small-loop: 10)")(
      "closure-tail-fraction", po::value(&tail_fraction),
      "draw this share of the loop closures wider (--closure-tail-factor), their Ω as the "
      "others' (0; vehicle, small-loop: 0.05)")(
      "closure-tail-factor", po::value(&tail_factor),
      "how much wider those closures' sigmas are, >= 1 (vehicle, small-loop: 6)")(
      "information-scale", po::value(&information_scale)->default_value(1),
      "write Ω = X × the information of the noise drawn, on every edge (odometry and loop "
      "closures): < 1 a cautious front end (e.g. 0.02: χ² at the truth averages 0.02 × dof), "
      "> 1 an over-confident one (e.g. 30)")(
      "input", po::value(&input), "outliers: the g2o or TORO graph to add false loop closures to")(
      "outliers", po::value(&fraction),
      "append round(FRACTION × loop closures) false loop closures (|i − j| > 1; half to even), "
      "each copying a real closure's information, measuring a random pose (translation within "
      "3 × the largest loop-closure translation component, at least 3; uniform rotation); "
      "also writes their labels ('i j' a line, file ids)")(
      "outlier-policy", po::value(&policy)->default_value("random"),
      "random: pose pairs drawn at random; local: pairs 10-50 poses apart; group: groups of 10 "
      "consecutive pairs (i+k, j+k) that all measure one false transform, so they agree")(
      "labels", po::value(&labels), "where the labels go (default: the output with .labels)")(
      "information", po::value(&information)->default_value("refuse"),
      "outliers: Ω of the input that are not positive definite: refuse | repair | isotropic");
  po::positional_options_description positional;
  positional.add("kind", 1);
  if (helpRequested(args, options)) return 0;
  const po::variables_map vm = parseArguments(args, options, positional);
  if (!(sigma_t > 0) || !(sigma_r > 0)) throw UsageError("noise sigmas must be positive");
  if (!(information_scale > 0) || !std::isfinite(information_scale)) {
    std::ostringstream os;
    os << "--information-scale must be finite and > 0, not '" << information_scale << "'";
    throw UsageError(os.str());
  }
  if (closure_probability != -1 && !(closure_probability >= 0 && closure_probability <= 1))
    throw UsageError("--closure-probability must be in [0, 1]");
  if (vm.count("closure-sigma-factor") &&
      (!(closure_sigma_factor > 0) || !std::isfinite(closure_sigma_factor))) {
    std::ostringstream os;
    os << "--closure-sigma-factor must be finite and > 0, not '" << closure_sigma_factor << "'";
    throw UsageError(os.str());
  }
  if (vm.count("closure-tail-fraction") && !(tail_fraction >= 0 && tail_fraction <= 1)) {
    std::ostringstream os;
    os << "--closure-tail-fraction must be in [0, 1], not '" << tail_fraction << "'";
    throw UsageError(os.str());
  }
  if (vm.count("closure-tail-factor") && !(tail_factor >= 1 && std::isfinite(tail_factor))) {
    std::ostringstream os;
    os << "--closure-tail-factor must be finite and >= 1, not '" << tail_factor << "'";
    throw UsageError(os.str());
  }
  // The noise of a kind: its preset's, with the flags given on top.
  auto noiseOf = [&](sim::NoiseModel preset) {
    if (!vm["sigma-t"].defaulted()) preset.sigma_translation = sigma_t;
    if (!vm["sigma-r"].defaulted()) preset.sigma_rotation = sigma_r;
    if (vm.count("closure-sigma-factor")) preset.closure_sigma_factor = closure_sigma_factor;
    if (vm.count("closure-tail-fraction")) preset.closure_tail_fraction = tail_fraction;
    if (vm.count("closure-tail-factor")) preset.closure_tail_factor = tail_factor;
    preset.information_scale = information_scale;
    return preset;
  };
  const sim::NoiseModel noise = noiseOf(sim::NoiseModel{sigma_t, sigma_r});

  OutlierRequest request;
  request.on = vm.count("outliers") > 0;
  if (!request.on) {
    for (const char* flag : {"outlier-policy", "labels"}) {
      if (!vm[flag].defaulted() && vm.count(flag)) {
        throw UsageError(std::string("--") + flag + " needs --outliers FRACTION");
      }
    }
  } else {
    if (!std::isfinite(fraction) || fraction < 0) {
      std::ostringstream os;
      os << "--outliers must be a finite fraction >= 0, not '" << fraction << "'";
      throw UsageError(os.str());
    }
    const auto parsed = sim::parseOutlierPolicy(policy);
    if (!parsed)
      throw UsageError("--outlier-policy must be random, local or group, not '" + policy + "'");
    request.options.fraction = fraction;
    request.options.policy = *parsed;
    request.options.seed = seed;
    request.labels = labels.empty()
                         ? std::filesystem::path(output).replace_extension(".labels").string()
                         : labels;
    if (request.labels == output) {
      throw UsageError("the labels would overwrite the output '" + output + "' (use --labels)");
    }
  }

  auto write = [&](const auto& simulation) {
    auto graph = simulation.graph;
    const std::string tail = plantOutliers(request, kind, &graph);
    writeG2oFile(output, graph, graph.poses);
    if (!truth_output.empty()) writeG2oFile(truth_output, graph, simulation.truth);
    printWritten(output, graph, tail);
  };
  if (kind == "outliers") {
    if (input.empty()) throw UsageError("generate outliers needs --input FILE");
    if (!request.on) throw UsageError("generate outliers needs --outliers FRACTION");
    for (const char* flag :
         {"truth", "poses", "grid", "size", "rings", "per-ring", "closure-probability",
          "closure-sigma-factor", "closure-tail-fraction", "closure-tail-factor"}) {
      if (vm.count(flag))
        throw UsageError(std::string("--") + flag + " does not apply to outliers");
    }
    for (const char* flag : {"information-scale", "dim"}) {
      if (!vm[flag].defaulted())
        throw UsageError(std::string("--") + flag + " does not apply to outliers");
    }
    ReadOptions read;
    read.information = parseInformationPolicy(information);
    std::visit(
        [&](auto graph) {
          // A file without VERTEX lines gets its odometry chain as the written estimate (what
          // `arbor batch` would start from), not the identity poses of the read graph.
          const bool had_vertices = graph.has_initial_estimate;
          if (!had_vertices) graph.poses = odometryInitialization(graph);
          const std::string tail = plantOutliers(request, input, &graph);
          writeG2oFile(output, graph, graph.poses);
          printWritten(output, graph,
                       tail + (had_vertices ? "" : "; VERTEX lines: the odometry chain"));
        },
        readGraphFile(input, read));
    return 0;
  }
  if (vm.count("input")) throw UsageError("--input applies to generate outliers only");
  const bool road = kind == "vehicle" || kind == "small-loop";
  if (!road && !vm["dim"].defaulted())
    throw UsageError("--dim applies to vehicle and small-loop only");
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
  } else if (road) {
    sim::RoadOptions o = kind == "vehicle" ? sim::vehicleOptions() : sim::smallLoopOptions();
    o.seed = seed;
    o.noise = noiseOf(o.noise);
    if (vm.count("poses")) o.poses = poses;
    if (closure_probability >= 0) o.closure_probability = closure_probability;
    if (o.poses < 2) throw UsageError("--poses must be at least 2, not " + std::to_string(poses));
    if (dim != 2 && dim != 3) throw UsageError("--dim must be 2 or 3, not " + std::to_string(dim));
    for (const char* flag : {"grid", "size", "rings", "per-ring"}) {
      if (vm.count(flag)) throw UsageError(std::string("--") + flag + " does not apply to " + kind);
    }
    if (dim == 2) {
      write(sim::roadWorld2(o));
    } else {
      write(sim::roadWorld3(o));
    }
  } else {
    throw UsageError("unknown kind '" + kind +
                     "' (manhattan, sphere, grid, vehicle, small-loop or outliers)");
  }
  return 0;
}

}  // namespace arbor::cli
