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
#include "arbor_slam/tools/cli/command_command.h"
#include "arbor_slam/tools/cli/commands.h"
#include "arbor_slam/tools/serve/lcm_tuning.h"
#include "arbor_slam/tools/serve/serve_service.h"

namespace arbor::cli {
namespace po = boost::program_options;

namespace {

using E = EdgeCommandOptions;

const char* const kCommandSection = "Command";

OptionTable<E> makeEdgeCommandTable() {
  constexpr Tier kCommon = Tier::kCommon, kAdvanced = Tier::kAdvanced;
  // --seq: no default of its own (the clock's milliseconds are taken).
  OptionSpec<E> seq = numberOption<E>(
      "seq", kAdvanced, kCommandSection, "Q",
      "this sender's command seq, >= 1 and rising (default: milliseconds since the epoch)",
      [](auto& o) -> auto& { return o.seq; }, Condition{">= 1", [](double x) { return x >= 1; }});
  seq.get = [](const E& o) -> std::optional<std::string> {
    if (o.seq > 0) return std::to_string(o.seq);
    return std::nullopt;
  };
  return {
      switchOption<E>(
          "wait", kCommon, kCommandSection,
          "wait for the service's status naming this command; print its result, exit 1 if refused",
          [](auto& o) -> auto& { return o.wait; }, true),
      numberOption<E>(
          "timeout", kCommon, kCommandSection, "S", "seconds for --wait",
          [](auto& o) -> auto& { return o.timeout_s; },
          Condition{"> 0", [](double x) { return x > 0; }}),
      switchOption<E>(
          "json", kCommon, kCommandSection, "print one JSON object",
          [](auto& o) -> auto& { return o.json; }, true),
      numberOption<E>(
          "sender", kAdvanced, kCommandSection, "ID", "sender id",
          [](auto& o) -> auto& { return o.sender; },
          Condition{"a number", [](double) { return true; }}),
      seq,
  };
}

FlagSet edgeCommandFlagSet(E* o) {
  FlagSet flags(
      "arbor command disable|enable FROM TO [options]\n"
      "       arbor command covariance ID [ID2] [options]   (arbor command covariance --help)",
      {"arbor command disable 120 340 --lcm-url tcpq://127.0.0.1:7700 --wait",
       "arbor command enable 120 340 --key deploy.key --wait --json"});
  flags.positional("kind", po::value(&o->kind)->required());
  flags.positional("from", po::value(&o->from)->required());
  flags.positional("to", po::value(&o->to)->required());
  flags.add(busClientOptionTable());
  flags.add(edgeCommandOptionTable());
  return flags;
}

}  // namespace

const OptionTable<EdgeCommandOptions>& edgeCommandOptionTable() {
  static const OptionTable<EdgeCommandOptions> table = makeEdgeCommandTable();
  return table;
}

std::vector<FlagInfo> edgeCommandFlags() {
  E o;
  return edgeCommandFlagSet(&o).flags();
}

std::optional<EdgeCommandOptions> parseEdgeCommandLine(const std::vector<std::string>& args) {
  E o;
  const FlagSet flags = edgeCommandFlagSet(&o);
  const std::optional<po::variables_map> parsed = flags.parse(args);
  if (!parsed) return std::nullopt;
  readOptions(busClientOptionTable(), *parsed, &o.bus);
  readOptions(edgeCommandOptionTable(), *parsed, &o);
  if (o.kind != "disable" && o.kind != "enable")
    throw UsageError("'" + o.kind + "' is not disable or enable");
  if (o.from < 0 || o.to < 0) throw UsageError("pose ids must be >= 0");
  if (o.from == o.to) throw UsageError("FROM and TO are both " + std::to_string(o.from));
  return o;
}

int commandCommand(const std::vector<std::string>& args) {
  if (!args.empty() && args[0] == "covariance")
    return covarianceCommand(std::vector<std::string>(args.begin() + 1, args.end()));
  const std::optional<EdgeCommandOptions> options = parseEdgeCommandLine(args);
  if (!options) return 0;
  const std::string &kind = options->kind, &url = options->bus.url, &prefix = options->bus.prefix,
                    &key_file = options->bus.key_file;
  const Key from = options->from, to = options->to;
  const std::int64_t sender = options->sender;
  const std::int64_t seq = options->seq > 0 ? options->seq : serve::nowMicros() / 1000;
  const bool wait = options->wait, json = options->json;
  const double timeout_s = options->timeout_s;
  StreamEdgeCommand c;
  c.kind = kind == "disable" ? StreamEdgeCommand::Kind::kDisable : StreamEdgeCommand::Kind::kEnable;
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
