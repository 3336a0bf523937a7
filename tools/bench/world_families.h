// The families of generated worlds of issue 52's held-out protocol (`arbor bench robust
// --family NAME --seeds A-B`): each a road world preset (tools/generator/road_world.h) and a
// range of information scales X (Ω written = X · the information of the noise drawn, on every
// edge), X drawn per seed, log-uniform in the range and rounded to three significant digits,
// so that `arbor generate KIND --dim D --seed S --information-scale X` writes the same world.
//
//   vehicle         vehicleOptions(): 3,000 poses, closures under 2% of the edges; X in
//                   [0.01, 0.05] (Ω 20–100× cautious, as the car graphs of issue 52);
//   small-loop      smallLoopOptions(): 1,000 poses, about 100 closures; X in [0.01, 0.05];
//   over-confident  smallLoopOptions()'s world, X in [20, 50] (Ω 20–50× too large).
//
// A world of seed S has its false closures planted with seed S too (as `arbor generate ...
// --seed S --outliers F` does). Seeds 1–3 are the tuning seeds; 4–10 are held out.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "arbor_slam/tools/generator/road_world.h"

namespace arbor::bench {

struct WorldFamily {
  std::string name;        ///< "vehicle"
  std::string kind;        ///< the `arbor generate` kind of its worlds: vehicle | small-loop
  sim::RoadOptions world;  ///< the preset (its seed and noise.information_scale set per world)
  double scale_low = 1, scale_high = 1;  ///< the range of X
};

/// "vehicle", "small-loop", "over-confident".
std::vector<std::string> worldFamilyNames();

/// The family of that name; nullopt for any other.
std::optional<WorldFamily> worldFamily(const std::string& name);

/// X of the family's world of `seed` (header comment).
double familyInformationScale(const WorldFamily& family, std::uint64_t seed);

/// The options of the family's world of `seed` (seed and information scale set).
sim::RoadOptions familyWorldOptions(const WorldFamily& family, std::uint64_t seed);

/// "vehicle-2d-s1": the name of a family's world (and the base of its bench cases).
std::string familyWorldName(const WorldFamily& family, int dim, std::uint64_t seed);

/// A seed range "A-B" or one seed "A" (1 ≤ A ≤ B); std::invalid_argument naming the text
/// otherwise.
std::vector<std::uint64_t> parseSeedRange(const std::string& text);

}  // namespace arbor::bench
