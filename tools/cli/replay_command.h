// `arbor replay`'s command line, parsed apart from running it (tests read the options it gives).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "arbor_slam/bayestree/incremental_smoother.h"
#include "arbor_slam/bayestree/online_gnc.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/io/trajectory_writer.h"
#include "arbor_slam/tools/cli/flag_set.h"
#include "arbor_slam/tools/cli/robust_flags.h"
#include "arbor_slam/tools/refine/batch_solvers.h"

namespace arbor::cli {

struct ReplayCommandLine {
  std::string file, output, latency_csv, step = "edge";
  TrajectoryFormat format = TrajectoryFormat::kG2o;  ///< --format, or --output's extension
  std::string stamps_file;  ///< --stamps FILE: TUM's times (io/stamps_file.h)
  std::string covariances;  ///< --covariances FILE: every pose's marginal at the end
  bool json = false, finalize = true, reseed = false;
  bool bounded_heap = false;  ///< --bounded-heap: arbor::useBoundedHeap before reading the file
  std::optional<refine::BatchSolver> batch;  ///< --batch: a row that refines; none: no loop
  int batch_every = 0;
  /// --batch-sync: each batch on the replay thread at its snapshot (BatchLoopSettings::
  /// synchronous): the same runs on any machine
  bool batch_sync = false;
  int first_update_edges = 0;  ///< --first-update-edges: a map of that many edges loaded at once
  std::string initial = "odometry";  ///< --initial odometry|file: where new poses start
  SmootherOptions smoother;          ///< tools/cli/smoother_flags.h
  RobustFlags robust;                ///< tools/cli/robust_flags.h: online GNC per loop closure
  std::string edge_choices;          ///< --edge-choices FILE (io/edge_choice_file.h), with --robust
  /// --entry, --noise-scale, --warm-up and --corroboration-window (with --robust; read by
  /// readOnlineRobustFlags): the online GNC's options but the kernel and threshold, which are
  /// `robust`'s.
  RobustOptions online;
  ReadOptions read;
};

/// The options of `arbor replay ARGS`; nullopt (after printing the help) on --help. Throws
/// UsageError on anything unknown, missing or malformed, naming the flag and the value.
std::optional<ReplayCommandLine> parseReplayCommandLine(const std::vector<std::string>& args);

/// Every flag of `arbor replay`, as --help-all lists them.
std::vector<FlagInfo> replayFlags();

}  // namespace arbor::cli
