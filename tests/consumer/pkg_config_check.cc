// Compiled with nothing but `pkg-config --cflags --libs arbor-slam` against an installed prefix
// (tests/consumer/run_consumer_test.cmake): reads a pose-graph file (arbor_io), evaluates F at
// its estimate (arbor_core) and encodes an LCM estimate message (arbor_lcm and lcm-gen's
// installed "arbor/estimate_t.hpp"). Prints "poses N edges M F x bytes B".
#include <iostream>
#include <variant>

#include <arbor_slam/core/pose_graph.h>
#include <arbor_slam/io/lcm_messages.h>
#include <arbor_slam/io/pose_graph_file.h>

int main(int argc, char** argv) {
  if (argc != 2) return 2;
  const arbor::AnyPoseGraph graph = arbor::readPoseGraphFile(argv[1]);
  std::visit(
      [](const auto& g) {
        arbor::estimate_t message{};
        message.total_poses = g.numPoses();
        message.F = arbor::objective(g, g.poses);
        std::cout << "poses " << g.numPoses() << " edges " << g.numEdges() << " F " << message.F
                  << " bytes " << arbor::encodeMessage(message).size() << "\n";
      },
      graph);
  return 0;
}
