// The per-edge report of robust smoothing as files: every loop closure `i j weight status` a
// line (command CLOSURES, into --snapshot-dir), or only the rejected ones `i j` a line
// (--rejected-out). Ids are the senders' pose ids; the order is the order the closures arrived.
#pragma once

#include <string>
#include <vector>

#include "arbor_slam/bayestree/online_gnc.h"

namespace arbor::serve {

/// `i j weight status` a line (status: inlier, outlier, trusted, excluded; weight with 17
/// significant digits). Throws std::runtime_error
/// naming the path if it cannot be written.
void writeClosureReport(const std::string& path, const std::vector<ClosureReport>& closures);

/// The outliers, `i j` a line. Throws std::runtime_error naming the path if it cannot be
/// written.
void writeRejectedEdges(const std::string& path, const std::vector<ClosureReport>& closures);

}  // namespace arbor::serve
