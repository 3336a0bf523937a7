// arbor-microbench: Google Benchmark microbenchmarks (run as `arbor bench micro ...`). Takes the
// usual --benchmark_* flags, plus --sizes=N,N,... for the graph sizes of BM_UpdateAtSize
// (default 500,1000,2000; at most 4000).
#include <cstring>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "arbor_slam/core/blas_threads.h"
#include "arbor_slam/tools/bench/micro/bench_graphs.h"
#include "arbor_slam/tools/cli/cli_common.h"

namespace {

constexpr int kMaxSize = 4000;

/// Parses "500,1000" into sizes; throws std::invalid_argument naming a bad entry.
std::vector<int> parseSizes(const std::string& list) {
  std::vector<int> sizes;
  std::stringstream in(list);
  for (std::string item; std::getline(in, item, ',');) {
    std::size_t used = 0;
    int n = 0;
    try {
      n = std::stoi(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != item.size() || n < 2 || n > kMaxSize) {
      throw std::invalid_argument("--sizes: '" + item + "' is not a size in [2, " +
                                  std::to_string(kMaxSize) + "]");
    }
    sizes.push_back(n);
  }
  return sizes;
}

}  // namespace

int main(int argc, char** argv) {
  arbor::useOneBlasThread();  // first thing: stops OpenBLAS's idle workers early
  std::vector<int> sizes = {500, 1000, 2000};
  std::vector<char*> rest;
  try {
    for (int k = 0; k < argc; ++k) {
      const char* prefix = "--sizes=";
      if (std::strncmp(argv[k], prefix, std::strlen(prefix)) == 0) {
        sizes = parseSizes(argv[k] + std::strlen(prefix));
      } else {
        rest.push_back(argv[k]);
      }
    }
  } catch (const std::exception& e) {
    std::cerr << "arbor-microbench: " << e.what() << "\n";
    return 2;
  }
  int rest_argc = static_cast<int>(rest.size());
  rest.push_back(nullptr);
  arbor::micro::registerUpdateAtSize(sizes);
  benchmark::Initialize(&rest_argc, rest.data());
  if (benchmark::ReportUnrecognizedArguments(rest_argc, rest.data())) return 2;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
