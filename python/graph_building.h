// Graph2 / Graph3 built in memory (docs/python.md, "Graphs in memory"): the empty constructor,
// add_pose, add_edge, add_pose_prior, add_position_prior, fix, pose, write and pickling, added
// to the classes graph_bindings.cc defines.
#pragma once

#include <pybind11/pybind11.h>

#include "graph_object.h"

namespace arbor::python {

/// Adds the in-memory building methods to the class of GraphObject<G> (G = SE2 or SE3).
template <class G>
void defineGraphBuilding(pybind11::class_<GraphObject<G>>& c);

}  // namespace arbor::python
