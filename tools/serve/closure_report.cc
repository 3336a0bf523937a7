#include "arbor_slam/tools/serve/closure_report.h"

#include <fstream>
#include <iomanip>
#include <stdexcept>

namespace arbor::serve {

void writeClosureReport(const std::string& path, const std::vector<ClosureReport>& closures) {
  std::ofstream out(path);
  out << std::setprecision(17);
  for (const ClosureReport& c : closures)
    out << c.from << " " << c.to << " " << c.weight << " " << toString(c.status) << "\n";
  out.flush();
  if (!out) throw std::runtime_error("cannot write the closure report " + path);
}

void writeRejectedEdges(const std::string& path, const std::vector<ClosureReport>& closures) {
  std::ofstream out(path);
  for (const ClosureReport& c : closures)
    if (c.status == ClosureStatus::kOutlier) out << c.from << " " << c.to << "\n";
  out.flush();
  if (!out) throw std::runtime_error("cannot write the rejected edges " + path);
}

}  // namespace arbor::serve
