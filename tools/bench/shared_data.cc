#include "arbor_slam/tools/bench/shared_data.h"

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <stdexcept>

namespace arbor::bench {

namespace fs = std::filesystem;

std::string sharedDirectory(const std::string& fallback) {
  const char* env = std::getenv("ARBOR_SHARED_DIR");
  return env && *env ? std::string(env) : fallback;
}

std::vector<std::string> sharedDatasets(const std::string& shared_dir) {
  std::vector<std::string> files;
  const fs::path dir = fs::path(shared_dir) / "datasets";
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return files;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    if (entry.path().extension() == ".g2o") files.push_back(entry.path().string());
  }
  std::sort(files.begin(), files.end(), [](const std::string& a, const std::string& b) {
    return fs::file_size(a) < fs::file_size(b);
  });
  return files;
}

std::vector<std::vector<std::string>> readReferenceRows(const std::string& shared_dir,
                                                        const std::string& name) {
  std::vector<std::vector<std::string>> rows;
  std::ifstream in(fs::path(shared_dir) / "reference" / name);
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#' || line.rfind("dataset", 0) == 0) continue;
    std::vector<std::string>& f = rows.emplace_back();
    std::istringstream row(line);
    for (std::string cell; std::getline(row, cell, '\t');) f.push_back(cell);
  }
  return rows;
}

std::map<std::string, Reference> readOptimumTable(const std::string& shared_dir) {
  std::map<std::string, Reference> table;
  for (const std::vector<std::string>& f : readReferenceRows(shared_dir, "optimum.tsv")) {
    // dataset dim F* certified lm_reaches replay_target
    if (f.size() < 6) continue;
    Reference r;
    r.F_star = std::strtod(f[2].c_str(), nullptr);
    r.certified = f[3] == "yes";
    r.lm_reaches = f[4] == "yes";
    r.replay_target = f[5] == "yes";
    table[f[0]] = r;
  }
  return table;
}

std::map<std::pair<std::string, std::string>, Anchor> readAnchorTable(
    const std::string& shared_dir) {
  std::map<std::pair<std::string, std::string>, Anchor> table;
  for (const std::vector<std::string>& f : readReferenceRows(shared_dir, "anchors.tsv")) {
    // dataset dim nodes edges run total_s p50 p90 p99 max iterations F peak_rss status
    if (f.size() < 14) continue;
    Anchor a;
    a.total_s = std::strtod(f[5].c_str(), nullptr);
    a.p50_ms = std::strtod(f[6].c_str(), nullptr);
    a.p99_ms = std::strtod(f[8].c_str(), nullptr);
    a.max_ms = std::strtod(f[9].c_str(), nullptr);
    a.F = std::strtod(f[11].c_str(), nullptr);
    a.status = f[13];
    table[{f[0], f[4]}] = a;
  }
  return table;
}

std::string datasetName(const std::string& path) { return fs::path(path).stem().string(); }

std::vector<std::string> selectDatasets(const std::string& shared_dir, const std::string& only) {
  std::vector<std::string> files = sharedDatasets(shared_dir);
  if (files.empty()) throw std::runtime_error("no shared datasets at " + shared_dir + "/datasets");
  std::set<std::string> wanted;
  std::stringstream list(only);
  for (std::string item; std::getline(list, item, ',');) wanted.insert(item);
  if (wanted.empty()) return files;
  std::vector<std::string> selected;
  for (const auto& file : files) {
    if (wanted.count(datasetName(file))) selected.push_back(file);
  }
  return selected;
}

LoadedDataset loadDataset(const std::string& file) {
  LoadedDataset d{datasetName(file), file, PoseGraph2{}, 0, ""};
  ReadReport report;
  try {
    d.graph = readPoseGraphFile(file, ReadOptions{}, &report);
  } catch (const FileError&) {
    ReadOptions read;
    read.information = InformationPolicy::kRepair;
    report = ReadReport{};
    d.graph = readPoseGraphFile(file, read, &report);
    d.repaired = report.repaired;
    d.note = " (Ω repaired: " + std::to_string(report.repaired) + ")";
  }
  return d;
}

void forEachDataset(const std::vector<std::string>& files,
                    const std::function<void(const LoadedDataset&)>& visit) {
  for (const auto& file : files) visit(loadDataset(file));
}

void forEachDataset(const std::string& shared_dir, const std::string& only,
                    const std::function<void(const LoadedDataset&)>& visit) {
  forEachDataset(selectDatasets(shared_dir, only), visit);
}

}  // namespace arbor::bench
