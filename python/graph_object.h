// What a Graph2 / Graph3 Python object holds: the graph, the path it was read from and the
// reader's report (its warnings).
#pragma once

#include <string>

#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/io/pose_graph_file.h"

namespace arbor::python {

template <class G>
struct GraphObject {
  std::string path;
  PoseGraph<G> graph;
  ReadReport report;
};

}  // namespace arbor::python
