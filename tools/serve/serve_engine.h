// The smoother behind `arbor serve`: an OnlineSmoother of the stream's dimension, with the
// estimate turned into estimate_t messages (every pose, or only those changed since the last
// message) and written as g2o. Not thread-safe: the smoother thread owns it.
#pragma once

#include <memory>
#include <string>

#include "bayestree/online_smoother.h"
#include "io/lcm_messages.h"

namespace arbor::serve {

class Engine {
 public:
  virtual ~Engine() = default;
  virtual int dim() const = 0;
  /// Hands one validated edge to the smoother (the dimension must match).
  virtual EdgeResult add(const AnyStreamEdge& edge) = 0;
  virtual UpdateStats update() = 0;
  /// Relinearises everything and iterates to convergence (OnlineSmoother::finalize).
  virtual UpdateStats refine() = 0;
  virtual double objective() const = 0;
  virtual OnlineStats stats() const = 0;
  /// The estimate: every pose (`full`) or the poses whose value changed since the last call.
  /// F is filled (the objective) only for a full estimate, else NaN.
  virtual estimate_t estimate(bool full) = 0;
  /// Writes the estimate and the edges applied so far as g2o (the first pose is FIXed).
  virtual void writeG2o(const std::string& path) const = 0;
};

/// An engine for 2D (SE2) or 3D (SE3) poses; throws std::invalid_argument for another dim.
std::unique_ptr<Engine> makeEngine(int dim, const SmootherOptions& options);

}  // namespace arbor::serve
