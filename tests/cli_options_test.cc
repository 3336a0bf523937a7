// The command line in tiers (tools/cli/flag_set.h, tools/cli/option_table.h): --help lists the
// common tier within 60 lines, --help-all every flag; a --config file round-trips through
// --print-config; a prefix of a flag is refused on the command line and in a config file; the
// README's synopsis and docs/cli.md agree with the flags the tables declare.
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <functional>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <unistd.h>

#include "arbor_slam/tools/cli/bus_key_flag.h"
#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/command_command.h"
#include "arbor_slam/tools/cli/generate_command.h"
#include "arbor_slam/tools/cli/plot_command.h"
#include "arbor_slam/tools/cli/publish_command.h"
#include "arbor_slam/tools/cli/replay_command.h"
#include "arbor_slam/tools/cli/serve_command.h"
#include "arbor_slam/tools/cli/smoother_flags.h"

namespace arbor::cli {
namespace {

struct Command {
  const char* name;
  std::function<std::vector<FlagInfo>()> flags;
  /// Parses a command line (its positional arguments added): true when it gives options,
  /// false after printing --help or --help-all.
  std::function<bool(std::vector<std::string>)> run;
  /// Whether README.md's synopsis has a line of its own for it.
  bool in_readme = true;
  /// How its lines in README.md and docs/cli.md start; empty: "arbor NAME ".
  std::string synopsis = "";
};

std::string synopsisHead(const Command& c) {
  return c.synopsis.empty() ? std::string("arbor ") + c.name + " " : c.synopsis;
}

std::vector<Command> commands() {
  return {{"replay", replayFlags,
           [](std::vector<std::string> args) {
             args.insert(args.begin(), "graph.g2o");
             return parseReplayCommandLine(args).has_value();
           }},
          {"serve", serveFlags,
           [](const std::vector<std::string>& args) {
             return parseServeCommandLine(args).has_value();
           }},
          {"publish", publishFlags,
           [](std::vector<std::string> args) {
             args.insert(args.begin(), "graph.g2o");
             return parsePublishCommandLine(args).has_value();
           }},
          {"command", edgeCommandFlags,
           [](std::vector<std::string> args) {
             args.insert(args.begin(), {"disable", "1", "2"});
             return parseEdgeCommandLine(args).has_value();
           },
           true, "arbor command disable|enable "},
          {"command covariance", covarianceCommandFlags,
           [](std::vector<std::string> args) {
             args.insert(args.begin(), "1");
             return parseCovarianceCommandLine(args).has_value();
           },
           /*in_readme=*/false},
          {"plot", plotFlags,
           [](std::vector<std::string> args) {
             args.insert(args.begin(), "estimate.tum");
             return parsePlotCommandLine(args).has_value();
           }},
          {"generate", generateFlags, [](std::vector<std::string> args) {
             args.insert(args.begin(), {"manhattan", "-o", "out.g2o"});
             return parseGenerateCommandLine(args).has_value();
           }}};
}

std::string printed(const std::function<void()>& run) {
  ::testing::internal::CaptureStdout();
  run();
  return ::testing::internal::GetCapturedStdout();
}

bool lists(const std::string& help, const std::string& flag) {
  return std::regex_search(help, std::regex("(^|\\n)  (-., )?--" + flag + "( |\\n)"));
}

std::string tempPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() /
          ("arbor_cli_options_" + std::to_string(::getpid()) + "_" + name))
      .string();
}

void write(const std::string& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
}

std::string readText(const std::string& path) {
  std::ifstream in(path);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

TEST(CliOptions, HelpListsTheCommonTierWithinSixtyLinesAndHelpAllTheRest) {
  for (const Command& c : commands()) {
    const std::string help = printed([&] { EXPECT_FALSE(c.run({"--help"})); });
    const std::string all = printed([&] { EXPECT_FALSE(c.run({"--help-all"})); });
    EXPECT_LE(std::count(help.begin(), help.end(), '\n'), 60) << c.name << ":\n" << help;
    EXPECT_NE(help.find("examples:"), std::string::npos) << c.name;
    int common = 0;
    bool experimental = false;
    for (const FlagInfo& f : c.flags()) {
      EXPECT_TRUE(lists(all, f.name)) << c.name << " --help-all lacks --" << f.name;
      EXPECT_EQ(lists(help, f.name), f.tier == Tier::kCommon) << c.name << " --" << f.name;
      common += f.tier == Tier::kCommon;
      experimental = experimental || f.tier == Tier::kExperimental;
    }
    EXPECT_LE(common, 16) << c.name;
    // replay and serve have many flags, the others few (plot: 3).
    const bool large = std::string(c.name) == "replay" || std::string(c.name) == "serve";
    EXPECT_GE(common, large ? 8 : 3) << c.name;
    // Experimental flags are named in --help-all only, marked.
    EXPECT_EQ(all.find("[experimental]") != std::string::npos, experimental) << c.name;
    EXPECT_EQ(help.find("[experimental]"), std::string::npos) << c.name;
  }
}

// The help of replay and serve and the table give every smoother flag one text.
TEST(CliOptions, EverySmootherFlagHasItsTableTextInReplayAndServe) {
  auto squeeze = [](const std::string& text) {
    std::string out;
    for (char c : text) {
      const bool space = c == ' ' || c == '\n';
      if (!space || (!out.empty() && out.back() != ' ')) out += space ? ' ' : c;
    }
    return out;
  };
  for (const Command& c : commands()) {
    if (std::string(c.name) != "replay" && std::string(c.name) != "serve") continue;
    const std::string all = squeeze(printed([&] { EXPECT_FALSE(c.run({"--help-all"})); }));
    for (const auto& row : smootherOptionTable())
      EXPECT_NE(all.find(squeeze(row.help)), std::string::npos) << c.name << " --" << row.name;
  }
}

// What --print-config writes, --config reads back to the same options, and prints the same.
TEST(CliOptions, AConfigFileRoundTripsThroughPrintConfig) {
  const std::vector<std::string> args = {"--threads",
                                         "2",
                                         "--relinearize",
                                         "inline",
                                         "--robust",
                                         "--entry",
                                         "residual",
                                         "--batch",
                                         "lm",
                                         "--batch-every",
                                         "50",
                                         "--publish",
                                         "full",
                                         "--channel-prefix",
                                         "TEAM A ",
                                         "--rules-off",
                                         "end-word,rehold",
                                         "--dogleg",
                                         "--print-config"};
  std::ostringstream first;
  EXPECT_FALSE(parseServeCommandLine(args, first));
  const std::string file = tempPath("serve.toml");
  write(file, first.str());
  std::ostringstream second;
  EXPECT_FALSE(parseServeCommandLine({"--config", file, "--print-config"}, second));
  EXPECT_EQ(first.str(), second.str());
  EXPECT_NE(first.str().find("threads = 2\n"), std::string::npos) << first.str();
  EXPECT_NE(first.str().find("channel-prefix = \"TEAM A \"\n"), std::string::npos);

  std::vector<std::string> flags(args.begin(), args.end() - 1);
  const auto given = parseServeCommandLine(flags);
  const auto read = parseServeCommandLine({"--config", file});
  ASSERT_TRUE(given && read);
  EXPECT_EQ(read->options.smoother.threads, 2);
  EXPECT_TRUE(read->options.smoother.dogleg);
  EXPECT_TRUE(read->options.robust.has_value());
  EXPECT_EQ(read->options.robust->entry, EntryTest::kResidual);
  EXPECT_EQ(read->options.robust->rules_off, (RuleSet{RobustRule::kRehold, RobustRule::kEndWord}));
  EXPECT_EQ(read->options.batch.every, 50);
  EXPECT_EQ(read->options.channel_prefix, "TEAM A ");
  EXPECT_EQ(read->options.full_every, given->options.full_every);

  // The command line wins over the file.
  EXPECT_EQ(parseServeCommandLine({"--config", file, "--threads", "3"})->options.smoother.threads,
            3);
  // A file without --robust keeps the robust options it does not use as comments.
  std::ostringstream plain;
  EXPECT_FALSE(parseServeCommandLine({"--print-config"}, plain));
  EXPECT_NE(plain.str().find("# entry = \"innovation\"\n"), std::string::npos) << plain.str();
  write(file, plain.str());
  EXPECT_FALSE(parseServeCommandLine({"--config", file})->options.robust.has_value());
  std::filesystem::remove(file);
}

// A config file's bad line is refused naming the file, the line and what is wrong; a prefix of a
// flag is no key.
TEST(CliOptions, ABadConfigLineIsRefusedNamingFileAndLine) {
  const std::string file = tempPath("bad.toml");
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"threads = 2\nthread = 3\n", ":2: unknown option 'thread'"},
      {"# a comment\n\nrobus = true\n", ":3: unknown option 'robus'"},
      {"[smoother]\nthreads = 2\n", ":1: tables are not read"},
      {"dogleg = yes\n", ":1: dogleg must be true or false, not 'yes'"},
      {"threads = 2\nthreads = 3\n", ":2: threads is given twice"},
      {"publish = \"full\n", ":1: publish: expected a string closed by \""},
      {"threads 2\n", ":1: expected `key = value`"},
      {"config = \"other.toml\"\n", ":1: unknown option 'config'"},
  };
  for (const auto& [text, message] : cases) {
    write(file, text);
    try {
      parseServeCommandLine({"--config", file});
      ADD_FAILURE() << text << " accepted";
    } catch (const UsageError& e) {
      EXPECT_NE(std::string(e.what()).find(file + message), std::string::npos)
          << text << ": " << e.what();
    }
  }
  write(file, "threads = many\n");
  EXPECT_THROW(parseServeCommandLine({"--config", file}), UsageError);
  std::filesystem::remove(file);
  EXPECT_THROW(parseServeCommandLine({"--config", file}), UsageError);  // missing
}

// Only whole flag names are taken, --help-all's too.
TEST(CliOptions, APrefixOfAFlagIsRefused) {
  for (const std::vector<std::string>& args : {std::vector<std::string>{"--thread", "2"},
                                               {"--help-al"},
                                               {"--print-conf"},
                                               {"--conf", "x.toml"},
                                               {"--final-confirm", "0.3"}}) {
    try {
      parseServeCommandLine(args);
      ADD_FAILURE() << args.front() << " accepted";
    } catch (const UsageError& e) {
      EXPECT_NE(std::string(e.what()).find(args.front()), std::string::npos) << e.what();
    }
  }
}

// The other commands take whole names only as well: each prefix of one of its flags is refused,
// naming what was given.
TEST(CliOptions, APrefixOfAFlagIsRefusedByEveryCommand) {
  const std::vector<std::pair<std::string, std::vector<std::string>>> cases = {
      {"publish", {"--rat", "5"}},        {"publish", {"--wait-read"}},
      {"publish", {"--resend", "4"}},     {"publish", {"--lcm", "udpm://"}},
      {"command", {"--tim", "3"}},        {"command", {"--se", "7"}},
      {"command", {"--channel", "A_"}},   {"command covariance", {"--time", "3"}},
      {"command covariance", {"--js"}},   {"plot", {"--max-time", "0.1"}},
      {"plot", {"--out", "x.png"}},       {"generate", {"--pose", "10"}},
      {"generate", {"--outlier", "0.1"}}, {"generate", {"--closure-tail", "0.1"}},
  };
  for (const auto& [name, args] : cases) {
    for (const Command& c : commands()) {
      if (name != c.name) continue;
      try {
        c.run(args);
        ADD_FAILURE() << name << " " << args.front() << " accepted";
      } catch (const UsageError& e) {
        EXPECT_NE(std::string(e.what()).find(args.front()), std::string::npos) << e.what();
      }
    }
  }
  // The whole names are taken.
  const auto publish =
      parsePublishCommandLine({"graph.g2o", "--rate", "5", "--resend-window", "4"});
  ASSERT_TRUE(publish);
  EXPECT_EQ(publish->rate, 5);
  EXPECT_EQ(publish->resend_window, 4);
  const auto command = parseEdgeCommandLine({"enable", "3", "4", "--seq", "9", "--timeout", "2"});
  ASSERT_TRUE(command);
  EXPECT_EQ(command->kind, "enable");
  EXPECT_EQ(command->seq, 9);
  EXPECT_EQ(command->timeout_s, 2);
  EXPECT_EQ(parseEdgeCommandLine({"disable", "3", "4"})->seq, 0);  // the clock's, when sent
  const auto covariance = parseCovarianceCommandLine({"3", "4", "--json", "--key", "k"});
  ASSERT_TRUE(covariance);
  EXPECT_EQ(covariance->ids, (std::vector<Key>{3, 4}));
  EXPECT_TRUE(covariance->json);
  EXPECT_EQ(covariance->bus.key_file, "k");
  const auto plot = parsePlotCommandLine({"run/estimate.tum", "truth.tum", "--max-time-diff", "0"});
  ASSERT_TRUE(plot);
  EXPECT_EQ(plot->output, "run/estimate.png");
  EXPECT_EQ(plot->max_time_diff, 0);
  EXPECT_EQ(parsePlotCommandLine({"e.tum", "-o", "p.png"})->output, "p.png");
  const auto generate =
      parseGenerateCommandLine({"vehicle", "-o", "v.g2o", "--poses", "10", "--outliers", "0.2",
                                "--outlier-policy", "group"});
  ASSERT_TRUE(generate);
  EXPECT_EQ(generate->options.poses, 10);
  EXPECT_EQ(generate->options.fraction, 0.2);
  EXPECT_EQ(generate->options.policy, sim::OutlierPolicy::kGroup);
  EXPECT_EQ(generate->options.closure_probability, -1);  // vehicle's preset holds
  EXPECT_FALSE(generate->given.count("closure-probability"));
}

// `arbor keygen FILE` has no flags: its help is the usage and two examples; whatever else is
// given, a prefix of --help included, is refused.
// Whole numbers are read exactly: a seed past 2^53 keeps every digit, 2^64 − 1 is the largest
// seed, and a negative one, 2^64 or a fraction is refused naming the value.
TEST(CliOptions, AWholeNumberIsReadExactly) {
  const OptionTable<GenerateOptions>& table = generateOptionTable();
  const auto seed =
      std::find_if(table.begin(), table.end(), [](const auto& row) { return row.name == "seed"; });
  ASSERT_NE(seed, table.end());
  GenerateOptions o;
  seed->set(o, "9007199254740993");  // 2^53 + 1: a double would read 2^53
  EXPECT_EQ(o.seed, 9007199254740993ull);
  EXPECT_EQ(seed->get(o).value(), "9007199254740993");
  seed->set(o, "18446744073709551615");
  EXPECT_EQ(o.seed, 18446744073709551615ull);
  for (const std::string bad : {"-1", "18446744073709551616", "1.5", "", "7x"}) {
    try {
      seed->set(o, bad);
      ADD_FAILURE() << "accepted '" << bad << "'";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("'" + bad + "'"), std::string::npos) << e.what();
    }
  }
}

// serve --max-backlog sets the receive backlog's bound; 0 is refused naming the flag and value.
TEST(CliOptions, ServeMaxBacklogIsTheBacklogsBound) {
  const auto line = parseServeCommandLine({"--max-backlog", "1000"});
  ASSERT_TRUE(line.has_value());
  EXPECT_EQ(line->options.max_backlog, 1000u);
  EXPECT_EQ(parseServeCommandLine({})->options.max_backlog, std::size_t{1} << 18);
  try {
    parseServeCommandLine({"--max-backlog", "0"});
    ADD_FAILURE() << "--max-backlog 0 accepted";
  } catch (const UsageError& e) {
    EXPECT_NE(std::string(e.what()).find("--max-backlog must be in 1..1073741824, not '0'"),
              std::string::npos)
        << e.what();
  }
}

TEST(CliOptions, KeygenTakesOneFileAndNoFlags) {
  const std::string help = printed([] { EXPECT_FALSE(parseKeygenCommandLine({"--help"})); });
  EXPECT_EQ(help.rfind("usage: arbor keygen FILE", 0), 0u) << help;
  EXPECT_NE(help.find("examples:"), std::string::npos) << help;
  EXPECT_FALSE(parseKeygenCommandLine({"--help-all"}));
  EXPECT_EQ(parseKeygenCommandLine({"deploy.key"}), std::optional<std::string>("deploy.key"));
  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"k", "--hel"}, {"k", "--force"}, {"k", "other"}, {}}) {
    EXPECT_THROW(parseKeygenCommandLine(args), UsageError) << (args.empty() ? "" : args.back());
  }
}

// The flags named in a text: every `--name`.
std::set<std::string> flagsIn(const std::string& text) {
  std::set<std::string> out;
  const std::regex flag("--([a-z0-9][a-z0-9-]*)");
  for (auto it = std::sregex_iterator(text.begin(), text.end(), flag); it != std::sregex_iterator();
       ++it)
    out.insert((*it)[1]);
  return out;
}

// The lines of a fenced block in `path` from each one starting `first` up to the next line that
// starts with `arbor ` or is blank (a command of several lines, `arbor generate`'s, gives all).
std::string synopsisOf(const std::string& path, const std::string& first) {
  std::istringstream in(readText(path));
  std::string line, out;
  bool inside = false;
  while (std::getline(in, line)) {
    if (line.rfind(first, 0) == 0)
      inside = true;
    else if (line.rfind("arbor ", 0) == 0 || line.empty() || line == "```")
      inside = false;
    if (inside) out += line + "\n";
  }
  return out;
}

// The README's one line per command names only common flags of that command; docs/cli.md's
// synopsis names every flag of replay and serve and no other ("[smoother flags]": the smoother
// table's, listed once below the commands).
TEST(CliOptions, ReadmeSynopsisAndDocsAgreeWithTheTables) {
  const std::string root = ARBOR_SOURCE_DIR;
  std::set<std::string> smoother;
  for (const auto& row : smootherOptionTable()) smoother.insert(row.name);
  std::set<std::string> smoother_documented =
      flagsIn(synopsisOf(root + "/docs/cli.md", "smoother flags"));
  smoother_documented.erase("help");
  EXPECT_EQ(smoother_documented, smoother);
  for (const Command& c : commands()) {
    std::set<std::string> all, common;
    for (const FlagInfo& f : c.flags()) {
      all.insert(f.name);
      if (f.tier == Tier::kCommon) common.insert(f.name);
    }
    const std::string head = synopsisHead(c);
    const std::string readme = c.in_readme ? synopsisOf(root + "/README.md", head) : "";
    ASSERT_EQ(readme.empty(), !c.in_readme) << c.name;
    for (const std::string& f : flagsIn(readme))
      EXPECT_TRUE(common.count(f))
          << "README: arbor " << c.name << " --" << f << " is not a common flag";
    const std::string docs = synopsisOf(root + "/docs/cli.md", head);
    std::set<std::string> documented = flagsIn(docs);
    if (docs.find("[smoother flags]") != std::string::npos)
      documented.insert(smoother.begin(), smoother.end());
    documented.erase("help");  // --help and --help-all: every command's, no table's
    documented.erase("help-all");
    for (const std::string& f : all)
      EXPECT_TRUE(documented.count(f)) << "docs/cli.md: arbor " << c.name << " lacks --" << f;
    for (const std::string& f : documented)
      EXPECT_TRUE(all.count(f)) << "docs/cli.md: arbor " << c.name << " has no --" << f;
  }
}

}  // namespace
}  // namespace arbor::cli
