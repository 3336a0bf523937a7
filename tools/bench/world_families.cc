#include "arbor_slam/tools/bench/world_families.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>

#include "arbor_slam/tools/generator/random.h"

namespace arbor::bench {

std::vector<std::string> worldFamilyNames() { return {"vehicle", "small-loop", "over-confident"}; }

std::optional<WorldFamily> worldFamily(const std::string& name) {
  WorldFamily f;
  f.name = name;
  if (name == "vehicle") {
    f.kind = "vehicle";
    f.world = sim::vehicleOptions();
    f.scale_low = 0.01;
    f.scale_high = 0.05;
  } else if (name == "small-loop") {
    f.kind = "small-loop";
    f.world = sim::smallLoopOptions();
    f.scale_low = 0.01;
    f.scale_high = 0.05;
  } else if (name == "over-confident") {
    f.kind = "small-loop";
    f.world = sim::smallLoopOptions();
    f.scale_low = 20;
    f.scale_high = 50;
  } else {
    return std::nullopt;
  }
  return f;
}

double familyInformationScale(const WorldFamily& family, std::uint64_t seed) {
  // A stream of its own (not the world's nor the outliers'): one SplitMix64 step of the seed.
  std::uint64_t z = seed + 0x9e3779b97f4a7c15ull;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  z ^= z >> 31;
  sim::Random rng(z);
  const double u = rng.uniform();
  const double X = family.scale_low * std::pow(family.scale_high / family.scale_low, u);
  char text[32];
  std::snprintf(text, sizeof text, "%.3g", X);
  return std::strtod(text, nullptr);
}

sim::RoadOptions familyWorldOptions(const WorldFamily& family, std::uint64_t seed) {
  sim::RoadOptions o = family.world;
  o.seed = seed;
  o.noise.information_scale = familyInformationScale(family, seed);
  return o;
}

std::string familyWorldName(const WorldFamily& family, int dim, std::uint64_t seed) {
  return family.name + "-" + std::to_string(dim) + "d-s" + std::to_string(seed);
}

std::vector<std::uint64_t> parseSeedRange(const std::string& text) {
  const auto bad = [&] {
    return std::invalid_argument("--seeds must be A-B or A with 1 <= A <= B, not '" + text + "'");
  };
  const size_t dash = text.find('-');
  auto number = [&](const std::string& s) {
    if (s.empty() || s.find_first_not_of("0123456789") != std::string::npos || s.size() > 9)
      throw bad();
    return static_cast<std::uint64_t>(std::stoul(s));
  };
  const std::uint64_t a = number(text.substr(0, dash));
  const std::uint64_t b = dash == std::string::npos ? a : number(text.substr(dash + 1));
  if (a < 1 || b < a) throw bad();
  std::vector<std::uint64_t> seeds;
  for (std::uint64_t s = a; s <= b; ++s) seeds.push_back(s);
  return seeds;
}

}  // namespace arbor::bench
