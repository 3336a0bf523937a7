// A command's flags in tiers and help sections: `--help` lists the common tier, grouped, with
// examples; `--help-all` every flag; `--config FILE` reads flags from a file (config_file.h) under
// those of the command line; `--print-config` writes the options in force in the same format.
// Flags come from option tables (option_table.h) or are declared once with Boost's add_options.
// Only whole flag names are taken, never a prefix.
#pragma once

#include <iosfwd>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <boost/program_options.hpp>

#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/option_table.h"

namespace arbor::cli {

/// A flag as --help-all lists it.
struct FlagInfo {
  std::string name;  ///< without "--"
  Tier tier;
  std::string section;
};

class FlagSet {
 public:
  /// `usage`: "arbor replay FILE [options]"; `examples`: whole command lines for --help.
  FlagSet(std::string usage, std::vector<std::string> examples);

  /// Boost's add_options() for flags listed under `section` at `tier`; `needs`: the switch they
  /// need (--print-config comments them out while it is off).
  boost::program_options::options_description_easy_init add(Tier tier, const std::string& section,
                                                            const std::string& needs = "");
  /// Every row of `table`, each showing its value in `defaults`.
  template <class O>
  void add(const OptionTable<O>& table, const O& defaults = {});
  /// A positional argument taken up to `max_count` times (-1: any); the usage line names it, the
  /// help does not list it.
  void positional(const std::string& name, const boost::program_options::value_semantic* value,
                  int max_count = 1);
  /// --config FILE and --print-config.
  void allowConfig();

  std::vector<FlagInfo> flags() const;

  /// The values of `args`, under them those of --config FILE. nullopt after printing --help (or
  /// -h) or --help-all on stdout. Throws UsageError on anything unknown, missing or malformed.
  std::optional<boost::program_options::variables_map> parse(
      const std::vector<std::string>& args) const;

  /// With --print-config in `vm`: writes the options in force to `out` (what --config reads; a
  /// flag with no value, or whose needed switch is off, as a comment) and returns true.
  bool printConfig(const boost::program_options::variables_map& vm, std::ostream& out) const;

  void printHelp(std::ostream& out, bool all) const;

 private:
  struct Group {
    Tier tier;
    std::string section, needs;
    std::shared_ptr<boost::program_options::options_description> options;
  };
  std::vector<std::string> sections() const;  // in order of first appearance
  boost::program_options::options_description everything() const;

  std::string usage_;
  std::vector<std::string> examples_;
  std::vector<Group> groups_;
  std::shared_ptr<boost::program_options::options_description> hidden_;
  boost::program_options::positional_options_description positional_;
  bool config_ = false;
};

/// Every row of `table` in a plain description (no tiers: `arbor bench`'s commands).
template <class O>
void addOptions(const OptionTable<O>& table, boost::program_options::options_description& options,
                const O& defaults = {});

/// The rows of `table` given in `vm` (on the command line or in a config file), in table order,
/// into `options`. Throws UsageError "--NAME must be ..., not 'VALUE'" on a value a row refuses.
template <class O>
void readOptions(const OptionTable<O>& table, const boost::program_options::variables_map& vm,
                 O* options);

// Implementation.

// A row's value: a switch, or text shown with its value in `defaults`.
template <class O>
boost::program_options::value_semantic* optionValue(const OptionSpec<O>& spec, const O& defaults) {
  namespace po = boost::program_options;
  if (spec.arg.empty()) return po::bool_switch();
  auto* value = po::value<std::string>()->value_name(spec.arg);
  if (const std::optional<std::string> text = spec.get(defaults)) value->default_value(*text);
  return value;
}

template <class O>
void FlagSet::add(const OptionTable<O>& table, const O& defaults) {
  for (const OptionSpec<O>& spec : table)
    add(spec.tier, spec.section, spec.needs)(spec.name.c_str(), optionValue(spec, defaults),
                                             spec.help.c_str());
}

template <class O>
void addOptions(const OptionTable<O>& table, boost::program_options::options_description& options,
                const O& defaults) {
  for (const OptionSpec<O>& spec : table)
    options.add_options()(spec.name.c_str(), optionValue(spec, defaults), spec.help.c_str());
}

template <class O>
void readOptions(const OptionTable<O>& table, const boost::program_options::variables_map& vm,
                 O* options) {
  for (const OptionSpec<O>& spec : table) {
    const std::string& name = spec.name;
    if (!vm.count(name) || vm[name].defaulted()) continue;
    const boost::program_options::variable_value& value = vm[name];
    const std::string text =
        spec.arg.empty() ? (value.as<bool>() ? "true" : "false") : value.as<std::string>();
    try {
      spec.set(*options, text);
    } catch (const std::invalid_argument& e) {
      throw UsageError("--" + spec.name + " " + e.what());
    }
  }
}

}  // namespace arbor::cli
