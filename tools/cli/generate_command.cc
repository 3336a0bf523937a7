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
#include "arbor_slam/tools/cli/generate_command.h"
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

using G = GenerateOptions;

constexpr Condition kAny{"a number", [](double) { return true; }};

const char* const kGraphSection = "Graph";
const char* const kNoiseSection = "Noise";
const char* const kOutliersSection = "False loop closures";

// A number with no default of its own (the kind's preset's holds unless it is given).
template <class Access>
OptionSpec<G> presetNumber(std::string name, Tier tier, std::string section, std::string arg,
                           std::string help, Access access, Condition condition = kAny) {
  OptionSpec<G> spec = numberOption<G>(std::move(name), tier, std::move(section), std::move(arg),
                                       std::move(help), access, condition);
  spec.get = [](const G&) -> std::optional<std::string> { return std::nullopt; };
  return spec;
}

OptionTable<G> makeGenerateTable() {
  constexpr Tier kCommon = Tier::kCommon, kAdvanced = Tier::kAdvanced;
  constexpr Condition kFinitePositive{"finite and > 0",
                                      [](double x) { return x > 0 && std::isfinite(x); }};
  constexpr Condition kUnitInterval{"in [0, 1]", [](double x) { return x >= 0 && x <= 1; }};
  OptionSpec<G> information = informationOption<G>(
      kAdvanced, kOutliersSection, [](auto& o) -> auto& { return o.information; });
  information.help = "outliers: " + information.help + " in the input";
  return {
      textOption<G>(
          "truth", kCommon, kGraphSection, "FILE", "also write the ground truth poses as g2o",
          [](auto& o) -> auto& { return o.truth; }),
      numberOption<G>(
          "seed", kCommon, kGraphSection, "S",
          "random seed (of the graph and of its false loop closures)",
          [](auto& o) -> auto& { return o.seed; }, kAny),
      presetNumber(
          "poses", kCommon, kGraphSection, "N",
          "number of poses (manhattan: 3500, grid: 1000, vehicle: 3000, small-loop: 1000)",
          [](auto& o) -> auto& { return o.poses; }),
      // 2 or 3, checked with the kind (--dim applies to vehicle and small-loop only).
      numberOption<G>(
          "dim", kCommon, kGraphSection, "2|3",
          "vehicle, small-loop: 2 (SE2) or 3 (SE3, the road over gentle hills: height and pitch "
          "change)",
          [](auto& o) -> auto& { return o.dim; }, kAny),
      presetNumber(
          "grid", kAdvanced, kGraphSection, "N", "manhattan: world size in cells (10)",
          [](auto& o) -> auto& { return o.grid; }),
      presetNumber(
          "size", kAdvanced, kGraphSection, "N", "grid: lattice size per axis (6)",
          [](auto& o) -> auto& { return o.size; }),
      presetNumber(
          "rings", kAdvanced, kGraphSection, "N", "sphere: number of rings (20)",
          [](auto& o) -> auto& { return o.rings; }),
      presetNumber(
          "per-ring", kAdvanced, kGraphSection, "N", "sphere: poses per ring (50)",
          [](auto& o) -> auto& { return o.per_ring; }),
      presetNumber(
          "closure-probability", kAdvanced, kGraphSection, "P",
          "manhattan, grid, vehicle, small-loop: chance of a loop closure on a revisit (0.3 / "
          "0.5 / 0.8 / 0.6)",
          [](auto& o) -> auto& { return o.closure_probability; }, kUnitInterval),
      numberOption<G>(
          "information-scale", kCommon, kNoiseSection, "X",
          "write Ω = X × the information of the noise drawn, on every edge (odometry and loop "
          "closures): < 1 a cautious front end (e.g. 0.02: χ² at the truth averages 0.02 × dof), "
          "> 1 an over-confident one (e.g. 30)",
          [](auto& o) -> auto& { return o.information_scale; }, kFinitePositive),
      // > 0, checked with the other sigma ("noise sigmas must be positive").
      numberOption<G>(
          "sigma-t", kAdvanced, kNoiseSection, "M",
          "translation noise (m; vehicle, small-loop: 0.02)",
          [](auto& o) -> auto& { return o.sigma_t; }, kAny),
      numberOption<G>(
          "sigma-r", kAdvanced, kNoiseSection, "RAD",
          "rotation noise (rad; vehicle, small-loop: 0.002)",
          [](auto& o) -> auto& { return o.sigma_r; }, kAny),
      presetNumber(
          "closure-sigma-factor", kAdvanced, kNoiseSection, "F",
          "draw the loop closures (|i - j| > 1) with both sigmas times F, their Ω from that noise "
          "(1; vehicle, small-loop: 10)",
          [](auto& o) -> auto& { return o.closure_sigma_factor; }, kFinitePositive),
      presetNumber(
          "closure-tail-fraction", kAdvanced, kNoiseSection, "P",
          "draw this share of the loop closures wider (--closure-tail-factor), their Ω as the "
          "others' (0; vehicle, small-loop: 0.05)",
          [](auto& o) -> auto& { return o.tail_fraction; }, kUnitInterval),
      presetNumber(
          "closure-tail-factor", kAdvanced, kNoiseSection, "F",
          "how much wider those closures' sigmas are, >= 1 (vehicle, small-loop: 6)",
          [](auto& o) -> auto& { return o.tail_factor; },
          Condition{"finite and >= 1", [](double x) { return x >= 1 && std::isfinite(x); }}),
      presetNumber(
          "outliers", kCommon, kOutliersSection, "FRACTION",
          "append round(FRACTION × loop closures) false loop closures (|i − j| > 1; half to "
          "even), each copying a real closure's information, measuring a random pose "
          "(translation within 3 × the largest loop-closure translation component, at least 3; "
          "uniform rotation); also writes their labels ('i j' a line, file ids)",
          [](auto& o) -> auto& { return o.fraction; },
          Condition{"a finite fraction >= 0", [](double x) { return x >= 0 && std::isfinite(x); }}),
      wordOption<G>(
          "outlier-policy", kCommon, kOutliersSection, "random|local|group",
          "random: pose pairs drawn at random; local: pairs 10-50 poses apart; group: groups of "
          "10 consecutive pairs (i+k, j+k) that all measure one false transform, so they agree",
          [](auto& o) -> auto& { return o.policy; },
          [](const std::string& text) {
            const std::optional<sim::OutlierPolicy> policy = sim::parseOutlierPolicy(text);
            if (!policy)
              throw std::invalid_argument("must be random, local or group, not '" + text + "'");
            return *policy;
          },
          [](sim::OutlierPolicy p) { return sim::toString(p); }),
      textOption<G>(
          "labels", kCommon, kOutliersSection, "OUT.labels",
          "where the labels go (default: the output with .labels)",
          [](auto& o) -> auto& { return o.labels; }),
      textOption<G>(
          "input", kCommon, kOutliersSection, "FILE",
          "outliers: the g2o or TORO graph to add false loop closures to",
          [](auto& o) -> auto& { return o.input; }),
      information,
  };
}

FlagSet generateFlagSet(G* o) {
  FlagSet flags(
      "arbor generate manhattan|sphere|grid|vehicle|small-loop -o OUT.g2o [options]\n"
      "       arbor generate outliers --input FILE -o OUT.g2o --outliers FRACTION [options]",
      {"arbor generate vehicle --poses 2000 --dim 3 --seed 4 -o road.g2o",
       "arbor generate outliers --input data/sphere_3d.g2o --outliers 0.1 -o sphere_0.1.g2o"});
  flags.positional("kind", po::value(&o->kind)->required());
  flags.add(Tier::kCommon, kGraphSection)(
      "output,o", po::value(&o->output)->required()->value_name("OUT"), "g2o file to write");
  flags.add(generateOptionTable());
  return flags;
}

}  // namespace

const OptionTable<GenerateOptions>& generateOptionTable() {
  static const OptionTable<GenerateOptions> table = makeGenerateTable();
  return table;
}

std::vector<FlagInfo> generateFlags() {
  G o;
  return generateFlagSet(&o).flags();
}

std::optional<GenerateCommandLine> parseGenerateCommandLine(const std::vector<std::string>& args) {
  GenerateCommandLine line;
  const FlagSet flags = generateFlagSet(&line.options);
  std::optional<po::variables_map> parsed = flags.parse(args);
  if (!parsed) return std::nullopt;
  line.given = std::move(*parsed);
  const po::variables_map& vm = line.given;
  if (!vm.count("outliers")) {
    for (const char* flag : {"outlier-policy", "labels"}) {
      if (!vm[flag].defaulted() && vm.count(flag)) {
        throw UsageError(std::string("--") + flag + " needs --outliers FRACTION");
      }
    }
  }
  readOptions(generateOptionTable(), vm, &line.options);
  const G& o = line.options;
  if (!(o.sigma_t > 0) || !(o.sigma_r > 0)) throw UsageError("noise sigmas must be positive");
  return line;
}

int generateCommand(const std::vector<std::string>& args) {
  const std::optional<GenerateCommandLine> line = parseGenerateCommandLine(args);
  if (!line) return 0;
  const po::variables_map& vm = line->given;
  const G& opts = line->options;
  const std::string &kind = opts.kind, &output = opts.output, &truth_output = opts.truth,
                    &input = opts.input, &labels = opts.labels;
  const int poses = opts.poses, rings = opts.rings, per_ring = opts.per_ring, size = opts.size,
            grid = opts.grid, dim = opts.dim;
  const std::uint64_t seed = opts.seed;
  const double sigma_t = opts.sigma_t, sigma_r = opts.sigma_r,
               closure_probability = opts.closure_probability, fraction = opts.fraction,
               information_scale = opts.information_scale,
               closure_sigma_factor = opts.closure_sigma_factor, tail_fraction = opts.tail_fraction,
               tail_factor = opts.tail_factor;
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
  if (request.on) {
    request.options.fraction = fraction;
    request.options.policy = opts.policy;
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
    read.information = opts.information;
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
