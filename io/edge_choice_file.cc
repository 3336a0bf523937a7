#include "arbor_slam/io/edge_choice_file.h"

#include <cstdlib>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <istream>
#include <set>

#include "arbor_slam/io/line_fields.h"

namespace arbor {
namespace {

std::pair<Key, Key> pairKey(Key a, Key b) { return {std::min(a, b), std::max(a, b)}; }

}  // namespace

EdgeChoices readEdgeChoices(std::istream& in, const std::string& name) {
  EdgeChoices choices;
  io_detail::forEachFieldLine(
      in, name,
      [&](const std::vector<std::string_view>& fields, int number, const std::string& where) {
        if (fields.size() != 3 && fields.size() != 4) {
          throw FileError(where + "expected 'FROM TO TRUST [KERNEL]', found " +
                          std::to_string(fields.size()) + " fields");
        }
        Key ids[2];
        for (int k = 0; k < 2; ++k) {
          if (const char* why = io_detail::parseId(fields[k], &ids[k]))
            throw FileError(where + "pose id '" + std::string(fields[k]) + "' " + why);
        }
        if (ids[0] == ids[1]) throw FileError(where + "self-loop " + std::to_string(ids[0]));
        EdgeChoice c;
        c.line = number;
        const std::string trust(fields[2]);
        if (trust == "trusted") {
          c.trust = EdgeTrust::kTrusted;
        } else if (trust == "robust") {
          c.trust = EdgeTrust::kRobust;
        } else if (trust != "default") {
          throw FileError(where + "trust '" + trust + "' is not default, trusted or robust");
        }
        if (fields.size() == 4 && fields[3] != "default") {
          const std::string kernel(fields[3]);
          try {
            c.kernel = parseKernelKind(kernel);
          } catch (const std::invalid_argument&) {
            c.kernel = KernelKind::kNone;
          }
          if (c.kernel == KernelKind::kNone)
            throw FileError(where + "kernel '" + kernel +
                            "' is not default, tls, gm, cauchy or huber");
        }
        const auto [it, inserted] = choices.emplace(pairKey(ids[0], ids[1]), c);
        if (!inserted) {
          throw FileError(where + "a second choice for " + std::to_string(ids[0]) + " " +
                          std::to_string(ids[1]) + " (the first is on line " +
                          std::to_string(it->second.line) + ")");
        }
      });
  return choices;
}

EdgeChoices readEdgeChoicesFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw FileError(path + ": cannot open: " + std::strerror(errno));
  return readEdgeChoices(in, path);
}

EdgeChoice edgeChoice(const EdgeChoices& choices, Key from, Key to) {
  const auto it = choices.find(pairKey(from, to));
  return it == choices.end() ? EdgeChoice{} : it->second;
}

template <class G>
void checkEdgeChoices(const EdgeChoices& choices, const PoseGraph<G>& graph,
                      const std::string& name) {
  std::set<std::pair<Key, Key>> pairs;
  for (const auto& e : graph.edges) pairs.insert(pairKey(graph.ids[e.i], graph.ids[e.j]));
  for (const auto& [key, c] : choices) {
    if (!pairs.count(key)) {
      throw FileError(name + ":" + std::to_string(c.line) + ": " + std::to_string(key.first) + " " +
                      std::to_string(key.second) + " names no edge of the graph");
    }
  }
}

template <class G>
void applyEdgeChoices(const EdgeChoices& choices, const PoseGraph<G>& graph, GncOptions* gnc) {
  const int m = graph.numEdges();
  const bool by_rule_trusts_odometry = gnc->trust_odometry;
  gnc->trust_odometry = false;
  gnc->trusted.resize(m, 0);
  gnc->kernels.assign(m, KernelKind::kNone);
  for (int k = 0; k < m; ++k) {
    const auto& e = graph.edges[k];
    const EdgeChoice c = edgeChoice(choices, graph.ids[e.i], graph.ids[e.j]);
    const bool odometry = by_rule_trusts_odometry && std::abs(e.i - e.j) == 1;
    gnc->trusted[k] = c.trust == EdgeTrust::kTrusted ||
                      (c.trust == EdgeTrust::kByRule && (odometry || gnc->trusted[k]));
    gnc->kernels[k] = c.kernel;
  }
}

template void checkEdgeChoices(const EdgeChoices&, const PoseGraph<SE2>&, const std::string&);
template void applyEdgeChoices(const EdgeChoices&, const PoseGraph<SE2>&, GncOptions*);
template void applyEdgeChoices(const EdgeChoices&, const PoseGraph<SE3>&, GncOptions*);
template void checkEdgeChoices(const EdgeChoices&, const PoseGraph<SE3>&, const std::string&);

}  // namespace arbor
