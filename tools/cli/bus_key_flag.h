// The authenticated bus on the command line, in one place: `--key FILE` for every program that
// talks on the bus (serve, publish, command), and `arbor keygen FILE`. docs/lcm.md, "An
// authenticated bus".
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <boost/program_options.hpp>
#include <lcm/lcm-cpp.hpp>

#include "arbor_slam/tools/cli/option_table.h"
#include "arbor_slam/tools/serve/bus_auth.h"

namespace arbor::cli {

/// The bus as a client program sees it (`arbor publish`, `arbor command`): where, which channels,
/// which key.
struct BusClientOptions {
  std::string url;       ///< --lcm-url (empty: LCM's default)
  std::string prefix;    ///< --channel-prefix of the ARBOR_* channels
  std::string key_file;  ///< --key FILE (empty: an open bus)
};

/// The --help section of the bus flags.
extern const char* const kBusSection;

/// The client programs' bus flags, listed under kBusSection: --lcm-url and --key (common),
/// --channel-prefix (advanced).
const OptionTable<BusClientOptions>& busClientOptionTable();

/// Adds `--key FILE` (the deployment key file) to `desc`, stored in `*path`.
void addBusKeyFlag(boost::program_options::options_description& desc, std::string* path);
/// The same through a FlagSet's section (tools/cli/flag_set.h).
void addBusKeyFlag(boost::program_options::options_description_easy_init add, std::string* path);

/// The keys of `--key FILE`; none when `path` is empty. A bad file throws std::runtime_error
/// naming it and what is wrong (tools/serve/bus_key.h).
serve::BusKeyring readBusKeyFlag(const std::string& path);

/// This program's side of the bus for `--key FILE`; null when `path` is empty.
std::unique_ptr<serve::BusAuth> busAuthFromFlag(const std::string& path);

/// The key file of `arbor keygen ARGS`; nullopt after printing the help on --help or
/// --help-all. Throws UsageError on anything else but one FILE (it has no flags).
std::optional<std::string> parseKeygenCommandLine(const std::vector<std::string>& args);

/// Publishes `bytes` on `channel`, sealed when `auth` is set; lcm.publish's result (0: sent).
int publishOnBus(lcm::LCM& lcm, serve::BusAuth* auth, const std::string& channel,
                 const std::vector<std::uint8_t>& bytes);

/// A message received on `channel` as the program should read it: with `auth`, the message
/// inside a verified envelope (false when it does not verify: ignore it); without, as it came.
bool openFromBus(serve::BusAuth* auth, const std::string& channel, const lcm::ReceiveBuffer* rbuf,
                 const std::uint8_t** data, int* size);

}  // namespace arbor::cli
