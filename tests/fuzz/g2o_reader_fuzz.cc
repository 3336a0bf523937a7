// The g2o/TORO reader (io/pose_graph_file.h) on untrusted text: a graph, or a FileError naming
// "fuzz.g2o:line: …", never another exception, a crash or a hang; a graph read has its edges and
// priors on poses it holds. Each input is read under all three information policies.
#include <cstddef>
#include <cstdint>
#include <sstream>
#include <string>
#include <variant>

#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tests/fuzz/fuzz_checks.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace arbor;
  if (size > (1u << 16)) return 0;
  const std::string text(reinterpret_cast<const char*>(data), size);
  for (InformationPolicy policy :
       {InformationPolicy::kRefuse, InformationPolicy::kRepair, InformationPolicy::kIsotropic}) {
    std::istringstream in(text);
    ReadOptions options;
    options.information = policy;
    ReadReport report;
    try {
      const AnyPoseGraph graph = readPoseGraph(in, "fuzz.g2o", options, &report);
      std::visit(
          [&](const auto& g) {
            const std::size_t poses = g.poses.size();
            fuzz::require(g.ids.size() == poses, "ids and poses differ in number");
            fuzz::require(report.edge_lines.size() == g.edges.size(), "edge_lines");
            for (const auto& e : g.edges) {
              fuzz::require(e.i >= 0 && static_cast<std::size_t>(e.i) < poses && e.j >= 0 &&
                                static_cast<std::size_t>(e.j) < poses,
                            "an edge on a pose the graph does not hold");
            }
            for (const auto& p : g.pose_priors) {
              fuzz::require(p.i >= 0 && static_cast<std::size_t>(p.i) < poses,
                            "a pose prior on a pose the graph does not hold");
            }
            for (const auto& p : g.position_priors) {
              fuzz::require(p.i >= 0 && static_cast<std::size_t>(p.i) < poses,
                            "a position prior on a pose the graph does not hold");
            }
          },
          graph);
    } catch (const FileError& e) {
      fuzz::require(std::string(e.what()).rfind("fuzz.g2o", 0) == 0,
                    "a FileError that does not name the input", e.what());
    }
  }
  return 0;
}
