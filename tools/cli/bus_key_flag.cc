#include "arbor_slam/tools/cli/bus_key_flag.h"

#include <iostream>

#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/commands.h"
#include "arbor_slam/tools/cli/flag_set.h"

namespace arbor::cli {

namespace po = boost::program_options;

const char* const kBusKeyHelp =
    "deployment key file (arbor keygen): every message sent is signed, every message received "
    "must verify (docs/lcm.md, \"An authenticated bus\")";

const char* const kBusSection = "Bus";

const OptionTable<BusClientOptions>& busClientOptionTable() {
  using B = BusClientOptions;
  static const OptionTable<B> table = {
      textOption<B>(
          "lcm-url", Tier::kCommon, kBusSection, "URL", "LCM provider URL (default: LCM's default)",
          [](auto& o) -> auto& { return o.url; }),
      textOption<B>(
          "key", Tier::kCommon, kBusSection, "FILE", kBusKeyHelp,
          [](auto& o) -> auto& { return o.key_file; }),
      textOption<B>(
          "channel-prefix", Tier::kAdvanced, kBusSection, "P", "prefix of the ARBOR_* channels",
          [](auto& o) -> auto& { return o.prefix; }),
  };
  return table;
}

void addBusKeyFlag(po::options_description& desc, std::string* path) {
  addBusKeyFlag(desc.add_options(), path);
}

void addBusKeyFlag(po::options_description_easy_init add, std::string* path) {
  add("key", po::value(path)->value_name("FILE"), kBusKeyHelp);
}

serve::BusKeyring readBusKeyFlag(const std::string& path) {
  if (path.empty()) return {};
  return serve::readBusKeyFile(path);
}

std::unique_ptr<serve::BusAuth> busAuthFromFlag(const std::string& path) {
  if (path.empty()) return nullptr;
  return std::make_unique<serve::BusAuth>(serve::readBusKeyFile(path));
}

int publishOnBus(lcm::LCM& lcm, serve::BusAuth* auth, const std::string& channel,
                 const std::vector<std::uint8_t>& bytes) {
  if (auth == nullptr)
    return lcm.publish(channel, bytes.data(), static_cast<unsigned>(bytes.size()));
  const std::vector<std::uint8_t> sealed = auth->seal(channel, bytes.data(), bytes.size());
  return lcm.publish(channel, sealed.data(), static_cast<unsigned>(sealed.size()));
}

bool openFromBus(serve::BusAuth* auth, const std::string& channel, const lcm::ReceiveBuffer* rbuf,
                 const std::uint8_t** data, int* size) {
  *data = static_cast<const std::uint8_t*>(rbuf->data);
  *size = static_cast<int>(rbuf->data_size);
  if (auth == nullptr) return true;
  const serve::OpenedMessage opened = auth->open(channel, *data, rbuf->data_size);
  if (opened.problem != serve::AuthProblem::kNone) return false;
  *data = opened.data;
  *size = static_cast<int>(opened.size);
  return true;
}

FlagSet keygenFlagSet(std::string* path) {
  FlagSet flags(
      "arbor keygen FILE   (a new deployment key into FILE: 32 random bytes, hex, mode 0600;\n"
      "       never over an existing file; prints its id)",
      {"arbor keygen /etc/arbor/deploy.key",
       "arbor keygen deploy.key && arbor serve --key deploy.key"});
  flags.positional("file", po::value(path)->required());
  return flags;
}

std::optional<std::string> parseKeygenCommandLine(const std::vector<std::string>& args) {
  std::string path;
  if (!keygenFlagSet(&path).parse(args)) return std::nullopt;
  return path;
}

int keygenCommand(const std::vector<std::string>& args) {
  const std::optional<std::string> path = parseKeygenCommandLine(args);
  if (!path) return 0;
  const serve::BusKey key = serve::writeNewBusKeyFile(*path);
  std::cout << "key " << serve::busKeyIdText(key.id) << " written to " << *path << "\n";
  return 0;
}

}  // namespace arbor::cli
