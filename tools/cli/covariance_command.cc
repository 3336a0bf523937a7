// arbor command covariance ID [ID2]: asks `arbor serve` for the marginal covariance of pose ID
// (or the joint covariance of ID and ID2) with command COVARIANCE on ARBOR_COMMAND (the ids in
// its path, its utime the request) and prints the covariance_t answer from ARBOR_COVARIANCE
// (docs/lcm.md).
#include <algorithm>
#include <chrono>
#include <iomanip>
#include <iostream>
#include <memory>

#include <lcm/lcm-cpp.hpp>
#include <nlohmann/json.hpp>

#include "arbor_slam/io/lcm_messages.h"
#include "arbor_slam/tools/cli/answer_watcher.h"
#include "arbor_slam/tools/cli/bus_key_flag.h"
#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/command_command.h"
#include "arbor_slam/tools/cli/commands.h"
#include "arbor_slam/tools/serve/lcm_tuning.h"
#include "arbor_slam/tools/serve/serve_service.h"

namespace arbor::cli {
namespace po = boost::program_options;

namespace {

using C = CovarianceCommandOptions;

OptionTable<C> makeCovarianceTable() {
  const char* const section = "Command";
  return {
      numberOption<C>(
          "timeout", Tier::kCommon, section, "S", "seconds to wait for the answer",
          [](auto& o) -> auto& { return o.timeout_s; },
          Condition{"> 0", [](double x) { return x > 0; }}),
      switchOption<C>(
          "json", Tier::kCommon, section, "print one JSON object",
          [](auto& o) -> auto& { return o.json; }, true),
  };
}

FlagSet covarianceFlagSet(C* o) {
  FlagSet flags(
      "arbor command covariance ID [ID2] [options]   (one id: its marginal covariance; "
      "two: their joint covariance)",
      {"arbor command covariance 120 --lcm-url tcpq://127.0.0.1:7700",
       "arbor command covariance 120 340 --key deploy.key --json"});
  flags.positional("id", po::value(&o->ids)->required()->multitoken(), -1);
  flags.add(busClientOptionTable());
  flags.add(covarianceCommandOptionTable());
  return flags;
}

}  // namespace

const OptionTable<CovarianceCommandOptions>& covarianceCommandOptionTable() {
  static const OptionTable<CovarianceCommandOptions> table = makeCovarianceTable();
  return table;
}

std::vector<FlagInfo> covarianceCommandFlags() {
  C o;
  return covarianceFlagSet(&o).flags();
}

std::optional<CovarianceCommandOptions> parseCovarianceCommandLine(
    const std::vector<std::string>& args) {
  C o;
  const FlagSet flags = covarianceFlagSet(&o);
  const std::optional<po::variables_map> parsed = flags.parse(args);
  if (!parsed) return std::nullopt;
  readOptions(busClientOptionTable(), *parsed, &o.bus);
  readOptions(covarianceCommandOptionTable(), *parsed, &o);
  if (o.ids.size() != 1 && o.ids.size() != 2)
    throw UsageError("covariance needs one or two pose ids, not " + std::to_string(o.ids.size()));
  for (Key id : o.ids)
    if (id < 0) throw UsageError("pose ids must be >= 0, not " + std::to_string(id));
  return o;
}

int covarianceCommand(const std::vector<std::string>& args) {
  const std::optional<CovarianceCommandOptions> options = parseCovarianceCommandLine(args);
  if (!options) return 0;
  const std::vector<Key>& ids = options->ids;
  const std::string &url = options->bus.url, &prefix = options->bus.prefix,
                    &key_file = options->bus.key_file;
  const bool json = options->json;
  const double timeout_s = options->timeout_s;

  command_t c;
  c.utime = serve::nowMicros();  // the request the answer names
  c.command = command_t::COVARIANCE;
  c.path = std::to_string(ids[0]) + (ids.size() == 2 ? " " + std::to_string(ids[1]) : "");
  const std::int64_t request = c.utime;

  const std::unique_ptr<serve::BusAuth> auth = busAuthFromFlag(key_file);
  lcm::LCM lcm(url);
  if (!lcm.good()) throw std::runtime_error("cannot open LCM at '" + url + "'");
  serve::tuneLcmTransport(lcm, url);
  lcm::LCM listen(url);
  if (!listen.good()) throw std::runtime_error("cannot open LCM at '" + url + "'");
  serve::tuneLcmTransport(listen, url);
  const serve::Channels channels = serve::Channels::withPrefix(prefix);
  AnswerWatcher<covariance_t> watcher(
      listen, channels.covariance,
      [request](const covariance_t& m) { return m.request == request; }, auth.get());
  // Over a hub (tcpq) a subscription reaches the hub some time after subscribe() returns, and
  // an answer published before then is not forwarded to us: asked at once, 2 of 6 requests went
  // unanswered. So the command first sees a probe of its own (a covariance_t answering no
  // request: request −1, never a utime) come back on the answer channel, then asks, once.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  covariance_t probe;  // lcm-gen leaves its numbers unset
  probe.utime = request;
  probe.request = -1;
  probe.num_ids = 0;
  probe.update = 0;
  probe.dim = 0;
  probe.error = "probe: arbor command covariance waits for its subscription";
  const auto probe_bytes = encodeMessage(probe);
  bool subscribed = false;
  while (!subscribed && std::chrono::steady_clock::now() < deadline) {
    if (publishOnBus(lcm, auth.get(), channels.covariance, probe_bytes) != 0)
      throw std::runtime_error("LCM publish failed on " + channels.covariance);
    subscribed = watcher.waitAny(0.05);
  }
  if (!subscribed) {
    std::cerr << "arbor command: nothing came back on " << channels.covariance << " within "
              << timeout_s << " s (is the LCM hub or network up?)\n";
    return 1;
  }
  const auto bytes = encodeMessage(c);
  if (publishOnBus(lcm, auth.get(), channels.command, bytes) != 0)
    throw std::runtime_error("LCM publish failed on " + channels.command);
  covariance_t answer;
  const double left_s =
      std::chrono::duration<double>(deadline - std::chrono::steady_clock::now()).count();
  if (!watcher.waitAnswer(std::max(left_s, 0.0), &answer)) {
    std::cerr << "arbor command: no answer on " << channels.covariance << " within " << timeout_s
              << " s (is arbor serve running?)\n";
    return 1;
  }
  if (json) {
    nlohmann::json j = {{"ids", answer.ids},
                        {"request", answer.request},
                        {"update", answer.update},
                        {"dim", answer.dim},
                        {"matrix", answer.matrix}};
    if (!answer.error.empty()) j["error"] = answer.error;
    std::cout << j.dump() << std::endl;
  } else if (answer.error.empty()) {
    std::cout << (ids.size() == 1 ? "marginal covariance of " : "joint covariance of ") << ids[0]
              << (ids.size() == 2 ? " and " + std::to_string(ids[1]) : "") << " after update "
              << answer.update << " (" << answer.dim << "x" << answer.dim
              << ", per pose [translation; rotation]):\n"
              << std::setprecision(9);
    for (const auto& row : answer.matrix) {
      for (size_t k = 0; k < row.size(); ++k) std::cout << (k ? " " : "") << row[k];
      std::cout << "\n";
    }
  }
  if (!answer.error.empty()) {
    std::cerr << "arbor command: covariance refused: " << answer.error << "\n";
    return 1;
  }
  return 0;
}

}  // namespace arbor::cli
