// Test helpers for the shared datasets beside the checkout (../shared): their location and
// the reference optima. Tests that need them GTEST_SKIP() with the path when they are absent.
#pragma once

#include <cctype>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>

namespace arbor::testing {

inline std::string sharedDir() {
  const char* env = std::getenv("ARBOR_SHARED_DIR");
  return env && *env ? std::string(env) : std::string(ARBOR_SHARED_DIR);
}

inline std::string datasetPath(const std::string& name) {
  return sharedDir() + "/datasets/" + name + ".g2o";
}

inline bool datasetPresent(const std::string& name) {
  return std::filesystem::exists(datasetPath(name));
}

/// A dataset name as a GoogleTest parameter name ("parking-garage" → "parking_garage").
inline std::string testName(std::string name) {
  for (char& c : name) {
    if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
  }
  return name;
}

struct OptimumRow {
  double F_star = 0;
  bool certified = false, lm_reaches = false, replay_target = false;
};

/// reference/optimum.tsv by dataset name; empty if absent.
inline std::map<std::string, OptimumRow> optimumTable() {
  std::map<std::string, OptimumRow> table;
  std::ifstream in(sharedDir() + "/reference/optimum.tsv");
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#' || line.rfind("dataset", 0) == 0) continue;
    std::istringstream row(line);
    std::string name, dim, f, cert, lm, replay;
    std::getline(row, name, '\t');
    std::getline(row, dim, '\t');
    std::getline(row, f, '\t');
    std::getline(row, cert, '\t');
    std::getline(row, lm, '\t');
    std::getline(row, replay, '\t');
    table[name] = {std::strtod(f.c_str(), nullptr), cert == "yes", lm == "yes", replay == "yes"};
  }
  return table;
}

}  // namespace arbor::testing
