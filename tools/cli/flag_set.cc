#include "arbor_slam/tools/cli/flag_set.h"

#include <algorithm>
#include <iostream>
#include <set>
#include <sstream>

#include "arbor_slam/tools/cli/config_file.h"

namespace arbor::cli {

namespace po = boost::program_options;

namespace {

constexpr std::size_t kLineLength = 100;
constexpr std::size_t kNameColumn = 34;

// "-o, --output N (=x)": the left column of a flag's help line.
std::string flagColumn(const po::option_description& option) {
  // format_name() is "-o [ --output ]" with a short name, "--output" without.
  const std::string name = option.format_name();
  std::string left = "  ";
  if (name.rfind("--", 0) != 0) left += name.substr(0, name.find(' ')) + ", ";
  left += "--" + option.long_name();
  const std::string parameter = option.format_parameter();
  if (!parameter.empty()) left += " " + parameter;
  return left;
}

// Characters (not bytes) of UTF-8 text: β and χ² take one column each.
std::size_t columns(const std::string& text) {
  std::size_t n = 0;
  for (unsigned char c : text) n += (c & 0xC0) != 0x80;
  return n;
}

// `text` wrapped at kLineLength, its lines after the first indented to kNameColumn; a line
// break in `text` starts a new line, its leading spaces kept.
void printWrapped(std::ostream& out, std::string left, const std::string& text) {
  if (columns(left) + 1 >= kNameColumn) {
    out << left << "\n";
    left.clear();
  }
  left.resize(kNameColumn, ' ');
  std::istringstream paragraphs(text);
  std::string paragraph;
  bool first_paragraph = true;
  while (std::getline(paragraphs, paragraph)) {
    const std::size_t indent = std::min(paragraph.find_first_not_of(' '), paragraph.size());
    const std::string margin(kNameColumn + indent, ' ');
    std::string line = first_paragraph ? left : margin;
    first_paragraph = false;
    std::istringstream words(paragraph);
    std::string word;
    bool first = true;
    while (words >> word) {
      if (!first && columns(line) + 1 + columns(word) > kLineLength) {
        out << line << "\n";
        line = margin;
        first = true;
      }
      line += (first ? "" : " ") + word;
      first = false;
    }
    out << line << "\n";
  }
  if (first_paragraph) out << left << "\n";
}

// A stored value as the command line would write it.
std::string commandLineText(const boost::any& value) {
  if (const auto* s = boost::any_cast<std::string>(&value)) return *s;
  if (const auto* b = boost::any_cast<bool>(&value)) return *b ? "true" : "false";
  if (const auto* i = boost::any_cast<int>(&value)) return std::to_string(*i);
  if (const auto* l = boost::any_cast<long>(&value)) return std::to_string(*l);
  if (const auto* ll = boost::any_cast<long long>(&value)) return std::to_string(*ll);
  if (const auto* u = boost::any_cast<unsigned>(&value)) return std::to_string(*u);
  if (const auto* ul = boost::any_cast<unsigned long>(&value)) return std::to_string(*ul);
  if (const auto* d = boost::any_cast<double>(&value)) return option_detail::text(*d);
  throw std::logic_error("--print-config: a flag of a type it cannot write");
}

bool isConfigFlag(const std::string& name) { return name == "config" || name == "print-config"; }

}  // namespace

FlagSet::FlagSet(std::string usage, std::vector<std::string> examples)
    : usage_(std::move(usage)),
      examples_(std::move(examples)),
      hidden_(std::make_shared<po::options_description>()) {}

po::options_description_easy_init FlagSet::add(Tier tier, const std::string& section,
                                               const std::string& needs) {
  if (groups_.empty() || groups_.back().tier != tier || groups_.back().section != section ||
      groups_.back().needs != needs) {
    groups_.push_back({tier, section, needs, std::make_shared<po::options_description>()});
  }
  return groups_.back().options->add_options();
}

void FlagSet::positional(const std::string& name, const po::value_semantic* value, int max_count) {
  hidden_->add_options()(name.c_str(), value, "");
  positional_.add(name.c_str(), max_count);
}

void FlagSet::allowConfig() {
  config_ = true;
  add(Tier::kCommon, "Configuration")(
      "config", po::value<std::string>()->value_name("FILE"),
      "read flags from FILE, TOML's `flag = value` a line (the command line wins over it)")(
      "print-config", po::bool_switch(),
      "print the options in force in the format --config reads, and exit");
}

std::vector<std::string> FlagSet::sections() const {
  std::vector<std::string> out;
  for (const Group& g : groups_)
    if (std::find(out.begin(), out.end(), g.section) == out.end()) out.push_back(g.section);
  return out;
}

po::options_description FlagSet::everything() const {
  po::options_description all;
  for (const Group& g : groups_) all.add(*g.options);
  all.add(*hidden_);
  return all;
}

std::vector<FlagInfo> FlagSet::flags() const {
  std::vector<FlagInfo> out;
  for (const Group& g : groups_)
    for (const auto& option : g.options->options())
      out.push_back({option->long_name(), g.tier, g.section});
  return out;
}

void FlagSet::printHelp(std::ostream& out, bool all) const {
  out << "usage: " << usage_ << "\n";
  int others = 0;
  for (const std::string& section : sections()) {
    bool header = false;
    for (Tier tier : {Tier::kCommon, Tier::kAdvanced, Tier::kExperimental}) {
      for (const Group& g : groups_) {
        if (g.section != section || g.tier != tier) continue;
        if (!all && tier != Tier::kCommon) {
          others += static_cast<int>(g.options->options().size());
          continue;
        }
        for (const auto& option : g.options->options()) {
          if (!header) out << "\n" << section << ":\n";
          header = true;
          const std::string mark = tier == Tier::kExperimental ? "[experimental] " : "";
          printWrapped(out, flagColumn(*option), mark + option->description());
        }
      }
    }
  }
  if (!all && !examples_.empty()) {
    out << "\nexamples:\n";
    for (const std::string& e : examples_) out << "  " << e << "\n";
  }
  if (!all && others > 0)
    out << "\n"
        << others << (others == 1 ? " more flag" : " more flags")
        << " (advanced and experimental): --help-all\n";
}

std::optional<po::variables_map> FlagSet::parse(const std::vector<std::string>& args) const {
  for (const std::string& a : args) {
    if (a == "--help" || a == "-h" || a == "--help-all") {
      printHelp(std::cout, a == "--help-all");
      return std::nullopt;
    }
  }
  // No prefix guessing (Boost's unix_style allows it): `--thread 2` would be taken as
  // `--threads 2` today and refused as ambiguous once a flag with that prefix is added.
  constexpr int kStyle =
      po::command_line_style::unix_style ^ po::command_line_style::allow_guessing;
  const po::options_description all = everything();
  po::variables_map vm;
  try {
    po::store(
        po::command_line_parser(args).options(all).positional(positional_).style(kStyle).run(), vm);
    if (config_ && vm.count("config")) {
      const std::string path = vm["config"].as<std::string>();
      po::parsed_options parsed(&all);
      for (const ConfigEntry& e : readConfigFile(path)) {
        const po::option_description* option = all.find_nothrow(e.key, false);
        if (!option || isConfigFlag(e.key) || hidden_->find_nothrow(e.key, false))
          throw UsageError(path + ":" + std::to_string(e.line) + ": unknown option '" + e.key +
                           "'");
        const bool is_switch = option->semantic()->max_tokens() == 0;
        if (is_switch && e.value != "true" && e.value != "false")
          throw UsageError(path + ":" + std::to_string(e.line) + ": " + e.key +
                           " must be true or false, not '" + e.value + "'");
        parsed.options.emplace_back(e.key, std::vector<std::string>{e.value});
      }
      po::store(parsed, vm);  // after the command line's: where both give a flag, it wins
    }
    po::notify(vm);
  } catch (const po::error& e) {
    throw UsageError(e.what());
  }
  return vm;
}

bool FlagSet::printConfig(const po::variables_map& vm, std::ostream& out) const {
  if (!config_ || !vm.count("print-config") || !vm["print-config"].as<bool>()) return false;
  bool first = true;
  for (const std::string& section : sections()) {
    if (section == "Configuration") continue;
    out << (first ? "" : "\n") << "# " << section << "\n";
    first = false;
    for (const Group& g : groups_) {
      if (g.section != section) continue;
      const bool off = !g.needs.empty() && !(vm.count(g.needs) && vm[g.needs].as<bool>());
      for (const auto& option : g.options->options()) {
        const std::string& name = option->long_name();
        if (!vm.count(name)) {
          out << "# " << name << " =\n";
          continue;
        }
        out << (off ? "# " : "") << name << " = " << tomlValue(commandLineText(vm[name].value()))
            << "\n";
      }
    }
  }
  return true;
}

}  // namespace arbor::cli
