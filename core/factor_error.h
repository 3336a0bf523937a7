// A factor whose evaluation failed inside the smoother's update (or its refinement): its error
// function threw, or returned a non-finite value or a wrong shape. FactorError's what() names
// the factor (its index, its name, its keys) and the poses' values it was evaluated at; the
// original exception is nested (std::rethrow_if_nested, FactorError::rethrow_nested). The
// smoother throws it after undoing the update (docs/library.md, "When an update throws").
#pragma once

#include <exception>
#include <sstream>
#include <stdexcept>
#include <string>

namespace arbor {

class FactorError : public std::runtime_error, public std::nested_exception {
 public:
  /// Constructed inside the handler of the original exception, which it nests.
  FactorError(const std::string& what, int factor) : std::runtime_error(what), factor_(factor) {}
  /// The factor's index as IncrementalSmoother numbers it: factors() order, and numFactors() + k
  /// for the k-th factor queued since the last update (as setFactorWeight).
  int factor() const { return factor_; }

 private:
  int factor_;
};

/// Inside a handler: throws FactorError(text + ": " + what() of the exception being handled,
/// factor), which nests it.
[[noreturn]] inline void throwFactorError(const std::string& text, int factor) {
  std::string cause = "an exception not derived from std::exception";
  try {
    throw;
  } catch (const std::exception& e) {
    cause = e.what();
  } catch (...) {
  }
  throw FactorError(text + ": " + cause, factor);
}

/// "t = (x, y), ω = (θ)": a pose's translation and rotation (the tangent's rotational part of
/// Log) for messages.
template <class G>
std::string poseText(const G& x) {
  std::ostringstream s;
  s.precision(6);
  const auto t = x.translation();
  const auto tau = x.Log();
  s << "t = (";
  for (int k = 0; k < t.size(); ++k) s << (k ? ", " : "") << t[k];
  s << "), ω = (";
  for (int k = static_cast<int>(t.size()); k < tau.size(); ++k)
    s << (k > t.size() ? ", " : "") << tau[k];
  s << ")";
  return s.str();
}

/// "factor 12 ('range' on poses 3, 7) at pose 3 t = (..), ω = (..); pose 7 ...": a factor
/// (anything with name(), arity() and key(k)) and the values of its poses in x.
template <class F, class Poses>
std::string factorText(const F& f, int index, const Poses& x) {
  std::string s = "factor " + std::to_string(index) + " ('" + f.name() + "' on pose" +
                  (f.arity() > 1 ? "s " : " ");
  for (int k = 0; k < f.arity(); ++k) s += (k ? ", " : "") + std::to_string(f.key(k));
  s += ") at ";
  for (int k = 0; k < f.arity(); ++k)
    s += std::string(k ? "; " : "") + "pose " + std::to_string(f.key(k)) + " " +
         poseText(x[static_cast<size_t>(f.key(k))]);
  return s;
}

}  // namespace arbor
