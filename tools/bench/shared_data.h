// Locating the shared datasets (../shared beside the checkout) and their reference optima.
#pragma once

#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "arbor_slam/io/pose_graph_file.h"

namespace arbor::bench {

struct Reference {
  double F_star = 0;
  bool certified = false;
  bool lm_reaches = false;
  bool replay_target = false;
};

/// The shared directory: $ARBOR_SHARED_DIR if set, else `fallback`.
std::string sharedDirectory(const std::string& fallback);

/// Dataset files (*.g2o) in DIR/datasets, sorted by size (smallest first); empty if absent.
std::vector<std::string> sharedDatasets(const std::string& shared_dir);

/// The data rows of DIR/reference/NAME (tab-separated cells), without blank lines, `#`
/// comments and the `dataset…` header; empty if the file is absent.
std::vector<std::vector<std::string>> readReferenceRows(const std::string& shared_dir,
                                                        const std::string& name);

/// DIR/reference/optimum.tsv by dataset name (file stem); empty if absent.
std::map<std::string, Reference> readOptimumTable(const std::string& shared_dir);

/// One row of reference/anchors.tsv (a reference implementation's run on a dataset).
struct Anchor {
  double total_s = 0, p50_ms = 0, p99_ms = 0, max_ms = 0, F = 0;
  std::string status;
};

/// DIR/reference/anchors.tsv keyed by (dataset, run), e.g. ("M3500", "isam2_edge").
std::map<std::pair<std::string, std::string>, Anchor> readAnchorTable(
    const std::string& shared_dir);

/// "M3500" for ".../M3500.g2o".
std::string datasetName(const std::string& path);

/// The dataset files of sharedDatasets(shared_dir) whose name is in the comma-separated `only`
/// (all if empty). Throws std::runtime_error("no shared datasets at DIR/datasets") if there are
/// none at all (a filter matching nothing gives an empty list).
std::vector<std::string> selectDatasets(const std::string& shared_dir, const std::string& only);

/// A shared dataset as read for the benchmarks.
struct LoadedDataset {
  std::string name;  ///< datasetName(file)
  std::string file;
  AnyPoseGraph graph;
  int repaired = 0;  ///< information matrices repaired (cubicle)
  std::string note;  ///< " (Ω repaired: N)" when repaired, else empty
};

/// Reads a dataset; a file refused for indefinite information (cubicle) is read again with Ω
/// repaired (as `arbor batch --information repair`), and `note` says so.
LoadedDataset loadDataset(const std::string& file);

/// Loads each of `files` in turn and calls visit(dataset).
void forEachDataset(const std::vector<std::string>& files,
                    const std::function<void(const LoadedDataset&)>& visit);

/// forEachDataset(selectDatasets(shared_dir, only), visit).
void forEachDataset(const std::string& shared_dir, const std::string& only,
                    const std::function<void(const LoadedDataset&)>& visit);

}  // namespace arbor::bench
