// The typed results of OnlineSmoother2/3 that are not a library struct as they are
// (docs/python.md, "Results"); smoother_results.cc binds them with UpdateStats and OnlineStats.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "arbor_slam/core/pose_graph.h"
#include "conversions.h"

namespace arbor::python {

/// add_graph(): how many of the graph's edges, priors and factors were accepted, how many were
/// duplicates.
struct AddGraphResult {
  int accepted = 0, duplicate = 0;
};

/// One loop closure of closures() (bayestree/online_gnc.h ClosureReport), its status by name.
struct Closure {
  Key from_id = 0, to_id = 0;
  double weight = 1, residual = 0;
  std::string status;
  bool graduating = false;
};

/// refine(): the figures of a batch refinement (tools/refine/batch_refiner.h BatchRun), its ids
/// and its batch estimate.
struct RefineResult {
  int poses = 0, edges = 0;
  double F_incremental = 0, F_batch = 0, relative_gap = 0;
  std::string winner;
  double margin = 0, max_translation_diff = 0, max_rotation_diff = 0;
  int iterations = 0;
  double time_s = 0;
  std::optional<bool> certified;
  std::optional<int> rank;
  std::optional<double> lambda_min;
  bool robust = false;
  int judged = 0, rejected = 0;
  double inlier_threshold = 0;
  std::string rtr_skipped;
  bool reseeded = false, reseed_rejected = false;
  std::vector<Key> ids;
  RowMatrix estimate;
};

}  // namespace arbor::python
