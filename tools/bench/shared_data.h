// Locating the shared datasets (../shared beside the checkout) and their reference optima.
#pragma once

#include <map>
#include <optional>
#include <string>
#include <vector>

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

}  // namespace arbor::bench
