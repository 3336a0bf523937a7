// arbor command disable|enable FROM TO: takes an edge back from `arbor serve`, or gives it back,
// with one edge_command_t on ARBOR_EDGE_COMMANDS (docs/lcm.md); with --wait, waits for the
// service's status naming this command and prints what the smoother did.
#include <chrono>
#include <iostream>

#include <lcm/lcm-cpp.hpp>
#include <nlohmann/json.hpp>

#include "arbor_slam/io/lcm_messages.h"
#include "arbor_slam/tools/cli/answer_watcher.h"
#include "arbor_slam/tools/cli/bus_key_flag.h"
#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/commands.h"
#include "arbor_slam/tools/serve/lcm_tuning.h"
#include "arbor_slam/tools/serve/serve_service.h"

namespace arbor::cli {
namespace po = boost::program_options;

int commandCommand(const std::vector<std::string>& args) {
  if (!args.empty() && args[0] == "covariance")
    return covarianceCommand(std::vector<std::string>(args.begin() + 1, args.end()));
  std::string kind, url, prefix, key_file;
  Key from = 0, to = 0;
  std::int64_t sender = 1, seq = 0;
  bool wait = false, json = false;
  double timeout_s = 10;
  po::options_description desc(
      "arbor command disable|enable FROM TO [options]\n"
      "arbor command covariance ID [ID2] [options]   (arbor command covariance --help)");
  desc.add_options()("help,h", "show this help")(
      "kind", po::value(&kind)->required(),
      "disable (take back every edge between FROM and TO) or enable (give them back)")(
      "from", po::value(&from)->required(), "pose id")("to", po::value(&to)->required(), "pose id")(
      "lcm-url", po::value(&url), "LCM provider URL (default: LCM's default)")(
      "channel-prefix", po::value(&prefix), "prefix of the ARBOR_* channels")(
      "sender", po::value(&sender)->default_value(1), "sender id")(
      "seq", po::value(&seq),
      "this sender's command seq, >= 1 and rising (default: milliseconds since the epoch)")(
      "wait", po::bool_switch(&wait),
      "wait for the service's status naming this command; print its result, exit 1 if refused")(
      "timeout", po::value(&timeout_s)->default_value(10), "seconds for --wait")(
      "json", po::bool_switch(&json), "print one JSON object");
  addBusKeyFlag(desc, &key_file);
  po::positional_options_description positional;
  positional.add("kind", 1).add("from", 1).add("to", 1);
  if (helpRequested(args, desc)) return 0;
  const auto vm = parseArguments(args, desc, positional);
  StreamEdgeCommand c;
  if (kind == "disable") {
    c.kind = StreamEdgeCommand::Kind::kDisable;
  } else if (kind == "enable") {
    c.kind = StreamEdgeCommand::Kind::kEnable;
  } else {
    throw UsageError("'" + kind + "' is not disable or enable");
  }
  if (from < 0 || to < 0) throw UsageError("pose ids must be >= 0");
  if (from == to) throw UsageError("FROM and TO are both " + std::to_string(from));
  if (!vm.count("seq")) seq = serve::nowMicros() / 1000;
  if (seq < 1) throw UsageError("--seq must be >= 1");
  if (!(timeout_s > 0)) throw UsageError("--timeout must be > 0");
  c.utime = serve::nowMicros();
  c.sender = sender;
  c.seq = seq;
  c.from = from;
  c.to = to;

  const std::unique_ptr<serve::BusAuth> auth = busAuthFromFlag(key_file);
  lcm::LCM lcm(url);
  if (!lcm.good()) throw std::runtime_error("cannot open LCM at '" + url + "'");
  serve::tuneLcmTransport(lcm, url);
  const serve::Channels channels = serve::Channels::withPrefix(prefix);
  // The watcher has its own instance (liblcm 1.3 delays what an instance receives while another
  // thread publishes on it) and sees a status before the command goes out: the service is up.
  std::unique_ptr<lcm::LCM> listen;
  std::unique_ptr<AnswerWatcher<status_t>> watcher;
  if (wait) {
    listen = std::make_unique<lcm::LCM>(url);
    if (!listen->good()) throw std::runtime_error("cannot open LCM at '" + url + "'");
    serve::tuneLcmTransport(*listen, url);
    // The status whose last command is (sender, seq) answers it.
    watcher = std::make_unique<AnswerWatcher<status_t>>(
        *listen, channels.status,
        [sender, seq](const status_t& s) {
          return s.last_command_sender == sender && s.last_command_seq == seq;
        },
        auth.get());
    if (!watcher->waitAny(timeout_s)) {
      std::cerr << "arbor command: no status from a server on " << channels.status << " within "
                << timeout_s << " s\n";
      return 1;
    }
  }
  const auto bytes = encodeMessage(makeEdgeCommandMessage(c));
  if (publishOnBus(lcm, auth.get(), channels.edge_commands, bytes) != 0)
    throw std::runtime_error("LCM publish failed on " + channels.edge_commands);
  status_t answer;
  const bool answered = wait && watcher->waitAnswer(timeout_s, &answer);
  const bool refused = answered && answer.last_command_result.rfind("refused", 0) == 0;
  if (json) {
    nlohmann::json j = {{"command", kind},  {"from", from}, {"to", to},
                        {"sender", sender}, {"seq", seq},   {"channel", channels.edge_commands}};
    if (wait) {
      j["answered"] = answered;
      if (answered) {
        j["result"] = answer.last_command_result;
        j["refused"] = refused;
        j["edges_disabled"] = answer.edges_disabled;
      }
    }
    std::cout << j.dump() << std::endl;
  } else {
    std::cout << "sent          " << kind << " " << from << " " << to << " (sender " << sender
              << " seq " << seq << ") on " << channels.edge_commands << "\n";
    if (answered)
      std::cout << "result        " << answer.last_command_result << " (" << answer.edges_disabled
                << " edges disabled now)\n";
  }
  if (wait && !answered) {
    std::cerr << "arbor command: no status naming sender " << sender << " seq " << seq << " within "
              << timeout_s << " s (refused by validation? see the service's log)\n";
    return 1;
  }
  return refused ? 1 : 0;
}

}  // namespace arbor::cli
