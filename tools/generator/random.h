// A seeded random source whose streams are the same on every platform and standard library
// (std::normal_distribution is not specified bit-for-bit, so we draw normals ourselves).
#pragma once

#include <cmath>
#include <cstdint>
#include <random>

namespace arbor::sim {

class Random {
 public:
  explicit Random(std::uint64_t seed) : engine_(seed) {}

  /// Uniform in [0, 1) from the top 53 bits of a mt19937_64 draw.
  double uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }

  /// Uniform integer in [0, n).
  int index(int n) { return static_cast<int>(uniform() * n); }

  /// Standard normal by the Box–Muller transform.
  double normal() {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    double u1 = uniform();
    while (u1 <= 0.0) u1 = uniform();
    const double u2 = uniform();
    const double r = std::sqrt(-2.0 * std::log(u1));
    spare_ = r * std::sin(2.0 * M_PI * u2);
    has_spare_ = true;
    return r * std::cos(2.0 * M_PI * u2);
  }

 private:
  std::mt19937_64 engine_;
  bool has_spare_ = false;
  double spare_ = 0.0;
};

}  // namespace arbor::sim
