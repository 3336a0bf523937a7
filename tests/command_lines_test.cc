// The command lines of `arbor replay` and `arbor serve` parsed without running them: every
// smoother flag (tools/cli/smoother_flags.h) reaches the same SmootherOptions field in both, a
// value the smoother refuses is refused naming the flag and the value; the batch-solver table
// (tools/refine/batch_solvers.h) names, parses and runs every solver.
#include <functional>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/replay_command.h"
#include "arbor_slam/tools/cli/serve_command.h"
#include "arbor_slam/tools/cli/smoother_flags.h"
#include "arbor_slam/tools/generator/graph_generator.h"
#include "arbor_slam/tools/refine/batch_solvers.h"
#include "arbor_slam/tools/serve/lcm_tuning.h"

namespace arbor::cli {
namespace {

SmootherOptions replaySmoother(std::vector<std::string> args) {
  args.insert(args.begin(), "graph.g2o");  // parsed, never read
  const auto line = parseReplayCommandLine(args);
  EXPECT_TRUE(line.has_value());
  return line ? line->smoother : SmootherOptions{};
}

SmootherOptions serveSmoother(const std::vector<std::string>& args) {
  const auto line = parseServeCommandLine(args);
  EXPECT_TRUE(line.has_value());
  return line ? line->options.smoother : SmootherOptions{};
}

// Every field of SmootherOptions, by name, for field-by-field comparisons.
struct Field {
  const char* name;
  std::function<double(const SmootherOptions&)> get;
};
const std::vector<Field>& fields() {
  static const std::vector<Field> all = {
      {"relinearize_threshold_translation",
       [](const SmootherOptions& o) { return o.relinearize_threshold_translation; }},
      {"relinearize_threshold_rotation",
       [](const SmootherOptions& o) { return o.relinearize_threshold_rotation; }},
      {"relinearize_skip", [](const SmootherOptions& o) { return o.relinearize_skip; }},
      {"wildfire_threshold", [](const SmootherOptions& o) { return o.wildfire_threshold; }},
      {"full_backsubstitution", [](const SmootherOptions& o) { return o.full_backsubstitution; }},
      {"rank_updates", [](const SmootherOptions& o) { return o.rank_updates; }},
      {"newest_last", [](const SmootherOptions& o) { return o.newest_last; }},
      {"dogleg", [](const SmootherOptions& o) { return o.dogleg; }},
      {"dogleg_initial_radius", [](const SmootherOptions& o) { return o.dogleg_initial_radius; }},
      {"dogleg_min_radius", [](const SmootherOptions& o) { return o.dogleg_min_radius; }},
      {"finalize_relative_tolerance",
       [](const SmootherOptions& o) { return o.finalize_relative_tolerance; }},
      {"finalize_max_iterations",
       [](const SmootherOptions& o) { return o.finalize_max_iterations; }},
      {"nested_dissection_min", [](const SmootherOptions& o) { return o.nested_dissection_min; }},
      {"threads", [](const SmootherOptions& o) { return o.threads; }},
      {"batch.top_share", [](const SmootherOptions& o) { return o.batch.top_share; }},
      {"batch.reorder_decay", [](const SmootherOptions& o) { return o.batch.reorder_decay; }},
      {"async.reorder_decay", [](const SmootherOptions& o) { return o.async.reorder_decay; }},
      {"cached_factors.max_ratio",
       [](const SmootherOptions& o) { return o.cached_factors.max_ratio; }},
  };
  return all;
}

void expectSame(const SmootherOptions& a, const SmootherOptions& b, const std::string& what) {
  for (const Field& f : fields()) EXPECT_EQ(f.get(a), f.get(b)) << what << ": " << f.name;
}

TEST(SmootherFlags, WithoutFlagsReplayAndServeRunTheSmootherDefaults) {
  expectSame(replaySmoother({}), SmootherOptions{}, "replay");
  expectSame(serveSmoother({}), SmootherOptions{}, "serve");
}

TEST(SmootherFlags, EveryFlagReachesItsFieldInReplayAndServeAlike) {
  const std::vector<std::string> args = {"--relinearize-threshold-translation",
                                         "0.3",
                                         "--relinearize-threshold-rotation",
                                         "0.2",
                                         "--relinearize-skip",
                                         "3",
                                         "--wildfire",
                                         "0.01",
                                         "--full-backsubstitution",
                                         "--no-rank-updates",
                                         "--no-newest-last",
                                         "--dogleg",
                                         "--dogleg-radius",
                                         "2",
                                         "--dogleg-min-radius",
                                         "0.0001",
                                         "--finalize-rel-tol",
                                         "0.001",
                                         "--finalize-max-iterations",
                                         "4",
                                         "--nested-dissection-min",
                                         "50",
                                         "--threads",
                                         "2",
                                         "--batch-top-share",
                                         "0.5",
                                         "--reorder-decay",
                                         "3",
                                         "--async-reorder-decay",
                                         "1.25",
                                         "--cached-factor-max-ratio",
                                         "8"};
  SmootherOptions expected;
  expected.relinearize_threshold_translation = 0.3;
  expected.relinearize_threshold_rotation = 0.2;
  expected.relinearize_skip = 3;
  expected.wildfire_threshold = 0.01;
  expected.full_backsubstitution = true;
  expected.rank_updates = false;
  expected.newest_last = false;
  expected.dogleg = true;
  expected.dogleg_initial_radius = 2;
  expected.dogleg_min_radius = 1e-4;
  expected.finalize_relative_tolerance = 1e-3;
  expected.finalize_max_iterations = 4;
  expected.nested_dissection_min = 50;
  expected.threads = 2;
  expected.batch.top_share = 0.5;
  expected.batch.reorder_decay = 3;
  expected.async.reorder_decay = 1.25;
  expected.cached_factors.max_ratio = 8;
  // Every field is set away from its default, so a flag that is dropped shows.
  for (const Field& f : fields()) EXPECT_NE(f.get(expected), f.get(SmootherOptions{})) << f.name;
  expectSame(replaySmoother(args), expected, "replay");
  expectSame(serveSmoother(args), expected, "serve");
}

TEST(SmootherFlags, ServeTakesTheFlagsItUsedToLack) {
  const SmootherOptions o =
      serveSmoother({"--dogleg", "--no-rank-updates", "--nested-dissection-min", "50"});
  EXPECT_TRUE(o.dogleg);
  EXPECT_FALSE(o.rank_updates);
  EXPECT_EQ(o.nested_dissection_min, 50);
  EXPECT_EQ(o.relinearize_skip, SmootherOptions{}.relinearize_skip);
}

// The robust layer judges closures against the estimate, which with async lags the job: the
// combination is refused naming both flags, in replay and serve alike.
TEST(SmootherFlags, RobustWithAsyncRelinearizationIsRefused) {
  for (const bool serve : {false, true}) {
    try {
      if (serve) {
        parseServeCommandLine({"--robust", "--relinearize", "async"});
      } else {
        parseReplayCommandLine({"graph.g2o", "--robust", "--relinearize", "async"});
      }
      ADD_FAILURE() << (serve ? "serve" : "replay") << " accepted --robust with async";
    } catch (const UsageError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("--robust"), std::string::npos) << what;
      EXPECT_NE(what.find("--relinearize inline"), std::string::npos) << what;
    }
  }
  EXPECT_NO_THROW(parseReplayCommandLine({"graph.g2o", "--robust"}));
  EXPECT_NO_THROW(parseReplayCommandLine({"graph.g2o", "--relinearize", "async"}));
}

TEST(SmootherFlags, AsyncRelinearizationReachesItsFieldsInReplayAndServeAlike) {
  const std::vector<std::string> args = {
      "--relinearize",         "async", "--async-min-variables",  "10", "--async-reorder", "inline",
      "--async-reorder-decay", "1.25",  "--async-job-iterations", "5"};
  for (const SmootherOptions& o : {replaySmoother(args), serveSmoother(args)}) {
    EXPECT_EQ(o.relinearize, RelinearizationMode::kAsync);
    EXPECT_EQ(o.async.min_variables, 10);
    EXPECT_FALSE(o.async.reorder_in_background);
    EXPECT_EQ(o.async.reorder_decay, 1.25);
    EXPECT_EQ(o.async.job_iterations, 5);
  }
  EXPECT_THROW(replaySmoother({"--relinearize", "async", "--async-reorder-decay", "0.9"}),
               UsageError);
  EXPECT_TRUE(SmootherOptions{}.async.reorder_in_background);
  EXPECT_TRUE(replaySmoother({"--relinearize", "async"}).async.reorder_in_background);
  EXPECT_EQ(replaySmoother({"--relinearize", "inline"}).relinearize, RelinearizationMode::kInline);
  EXPECT_EQ(SmootherOptions{}.relinearize, RelinearizationMode::kInline);
  EXPECT_THROW(replaySmoother({"--relinearize", "async", "--dogleg"}), UsageError);
}

// The bounded back-substitution: its flag reaches the field in replay and serve; it is refused
// beside a full back-substitution or dogleg (which need every Δ each update), and below 0.
TEST(SmootherFlags, SolveBudgetReachesItsFieldAndRefusesWhatNeedsEveryDelta) {
  EXPECT_EQ(SmootherOptions{}.solve_budget_mb, 0.0);
  EXPECT_EQ(replaySmoother({"--solve-budget-mb", "2.5"}).solve_budget_mb, 2.5);
  EXPECT_EQ(serveSmoother({"--solve-budget-mb", "2.5"}).solve_budget_mb, 2.5);
  EXPECT_THROW(replaySmoother({"--solve-budget-mb", "2", "--dogleg"}), UsageError);
  EXPECT_THROW(replaySmoother({"--solve-budget-mb", "2", "--full-backsubstitution"}), UsageError);
  EXPECT_THROW(replaySmoother({"--solve-budget-mb", "-1"}), UsageError);
  EXPECT_NO_THROW(replaySmoother({"--solve-budget-mb", "0", "--dogleg"}));
  // The robust layer judges closures against the estimate: refused as with async.
  EXPECT_THROW(parseReplayCommandLine({"graph.g2o", "--robust", "--solve-budget-mb", "1"}),
               UsageError);
  EXPECT_THROW(parseServeCommandLine({"--robust", "--solve-budget-mb", "1"}), UsageError);
}

TEST(SmootherFlags, OneThresholdSetsBothAndTheSpecificOneWins) {
  SmootherOptions o = replaySmoother({"--relinearize-threshold", "0.4"});
  EXPECT_EQ(o.relinearize_threshold_translation, 0.4);
  EXPECT_EQ(o.relinearize_threshold_rotation, 0.4);
  o = serveSmoother({"--relinearize-threshold", "0.4", "--relinearize-threshold-rotation", "0.2"});
  EXPECT_EQ(o.relinearize_threshold_translation, 0.4);
  EXPECT_EQ(o.relinearize_threshold_rotation, 0.2);
}

TEST(SmootherFlags, ABadValueIsRefusedNamingTheFlagAndTheValue) {
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"--relinearize-threshold", "-1"},
      {"--relinearize-threshold-translation", "-0.5"},
      {"--relinearize-threshold-rotation", "-0.5"},
      {"--relinearize-skip", "0"},
      {"--relinearize-skip", "abc"},
      {"--wildfire", "-0.1"},
      {"--dogleg-radius", "0"},
      {"--dogleg-min-radius", "-1"},
      {"--finalize-rel-tol", "-1"},
      {"--finalize-max-iterations", "0"},
      {"--nested-dissection-min", "-2"},
      {"--cached-factor-max-ratio", "-1"},
      {"--cached-factor-max-ratio", "inf"},
      {"--threads", "-1"},
      {"--batch-top-share", "0"},
      {"--batch-top-share", "1.5"},
      {"--reorder-decay", "0.5"},
      {"--relinearize", "sometimes"},
      {"--async-min-variables", "0"},
      {"--async-reorder", "later"},
      {"--async-job-iterations", "0"},
  };
  for (const auto& [flag, value] : bad) {
    for (const bool serve : {false, true}) {
      try {
        // FLAG=VALUE: program_options would take a separate "-1" for an option.
        if (serve) {
          parseServeCommandLine({flag + "=" + value});
        } else {
          parseReplayCommandLine({"graph.g2o", flag + "=" + value});
        }
        ADD_FAILURE() << (serve ? "serve " : "replay ") << flag << " " << value << " accepted";
      } catch (const UsageError& e) {
        const std::string message = e.what();
        EXPECT_NE(message.find(flag), std::string::npos) << message;
        EXPECT_NE(message.find(value), std::string::npos) << message;
      }
    }
  }
}

// --bounded-heap (core/heap_policy.h) is off unless given, in replay and serve alike.
TEST(HeapFlag, ReachesReplayAndServe) {
  EXPECT_FALSE(parseReplayCommandLine({"graph.g2o"})->bounded_heap);
  EXPECT_TRUE(parseReplayCommandLine({"graph.g2o", "--bounded-heap"})->bounded_heap);
  EXPECT_FALSE(parseServeCommandLine({})->bounded_heap);
  EXPECT_TRUE(parseServeCommandLine({"--bounded-heap"})->bounded_heap);
}

// --entry, --noise-scale, --corroboration-window, --finalize-rounds and --rules-off
// (tools/cli/robust_flags.h) reach the online robust options in replay and serve alike, are
// refused without --robust, and a bad value is refused naming it.
TEST(OnlineRobustFlags, ReachReplayAndServeAlikeAndNeedRobust) {
  const std::vector<std::string> args = {"--robust",
                                         "--entry",
                                         "residual",
                                         "--noise-scale",
                                         "given",
                                         "--corroboration-window",
                                         "7",
                                         "--finalize-rounds",
                                         "4",
                                         "--rules-off",
                                         "end-word,warm-up"};
  const RuleSet off{RobustRule::kEndWord, RobustRule::kWarmUp};
  std::vector<std::string> replay_args = args;
  replay_args.insert(replay_args.begin(), "graph.g2o");
  const auto replay = parseReplayCommandLine(replay_args);
  ASSERT_TRUE(replay.has_value());
  EXPECT_EQ(replay->online.entry, EntryTest::kResidual);
  EXPECT_EQ(replay->online.scale, NoiseScale::kGiven);
  EXPECT_EQ(replay->online.corroboration_window, 7);
  EXPECT_EQ(replay->online.finalize_rounds, 4);
  EXPECT_EQ(replay->online.rules_off, off);
  EXPECT_FALSE(replay->online.on(RobustRule::kEndWord));
  EXPECT_TRUE(replay->online.on(RobustRule::kRehold));
  const auto serve = parseServeCommandLine(args);
  ASSERT_TRUE(serve.has_value());
  ASSERT_TRUE(serve->options.robust.has_value());
  EXPECT_EQ(serve->options.robust->entry, EntryTest::kResidual);
  EXPECT_EQ(serve->options.robust->scale, NoiseScale::kGiven);
  EXPECT_EQ(serve->options.robust->corroboration_window, 7);
  EXPECT_EQ(serve->options.robust->finalize_rounds, 4);
  EXPECT_EQ(serve->options.robust->rules_off, off);
  // The defaults are the robust options' own.
  const auto plain = parseServeCommandLine({"--robust"});
  ASSERT_TRUE(plain.has_value() && plain->options.robust.has_value());
  EXPECT_EQ(plain->options.robust->entry, RobustOptions{}.entry);
  EXPECT_EQ(plain->options.robust->scale, RobustOptions{}.scale);
  EXPECT_EQ(plain->options.robust->corroboration_window, RobustOptions{}.corroboration_window);
  EXPECT_EQ(plain->options.robust->finalize_rounds, RobustOptions{}.finalize_rounds);
  EXPECT_TRUE(plain->options.robust->rules_off.empty());
  EXPECT_THROW(parseReplayCommandLine({"graph.g2o", "--rules-off", "end-word"}), UsageError);
  EXPECT_THROW(parseReplayCommandLine({"graph.g2o", "--finalize-rounds", "2"}), UsageError);
  for (const auto& [flag, bad] :
       std::vector<std::pair<std::string, std::string>>{{"--finalize-rounds", "0"},
                                                        {"--rules-off", "end-words"},
                                                        {"--rules-off", "warm-up,x"}}) {
    try {
      parseReplayCommandLine({"graph.g2o", "--robust", flag, bad});
      ADD_FAILURE() << flag << " " << bad << " accepted";
    } catch (const UsageError& e) {
      EXPECT_NE(std::string(e.what()).find(flag), std::string::npos) << e.what();
    }
  }
  // The rules removed after the held-out ablation (issue 52) are no flags any more.
  for (const char* gone : {"--end-backed-margin", "--left-out-backing-margin",
                           "--end-rejected-partners", "--warm-up", "--final-confirm-margin"})
    EXPECT_THROW(parseReplayCommandLine({"graph.g2o", "--robust", gone, "1"}), UsageError) << gone;
  EXPECT_EQ(parseReplayCommandLine({"graph.g2o", "--robust"})->online.corroboration_window,
            RobustOptions{}.corroboration_window);
  EXPECT_THROW(parseServeCommandLine({"--corroboration-window", "3"}), UsageError);
  EXPECT_THROW(parseReplayCommandLine({"graph.g2o", "--corroboration-window", "3"}), UsageError);
  try {
    parseReplayCommandLine({"graph.g2o", "--robust", "--corroboration-window", "-4"});
    ADD_FAILURE() << "--corroboration-window -4 accepted";
  } catch (const UsageError& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find("--corroboration-window"), std::string::npos) << message;
    EXPECT_NE(message.find("-4"), std::string::npos) << message;
  }
  for (const auto& [flag, value] : std::vector<std::pair<std::string, std::string>>{
           {"--entry", "residual"}, {"--noise-scale", "given"}, {"--rules-off", "rehold"}}) {
    EXPECT_THROW(parseServeCommandLine({flag, value}), UsageError) << flag;
    try {
      parseReplayCommandLine({"graph.g2o", flag, value});
      ADD_FAILURE() << flag << " accepted without --robust";
    } catch (const UsageError& e) {
      const std::string message = e.what();
      EXPECT_NE(message.find(flag + " needs --robust"), std::string::npos) << message;
    }
    try {
      parseServeCommandLine({"--robust", flag, "sometimes"});
      ADD_FAILURE() << flag << " sometimes accepted";
    } catch (const UsageError& e) {
      const std::string message = e.what();
      EXPECT_NE(message.find(flag), std::string::npos) << message;
      EXPECT_NE(message.find("sometimes"), std::string::npos) << message;
    }
  }
}

TEST(ServeCommandLine, BatchFlagsAndTheJournalPathWithoutStartingTheService) {
  const auto line = parseServeCommandLine(
      {"--batch", "rtr", "--batch-every", "7", "--reseed", "--journal", "/nonexistent/j"});
  ASSERT_TRUE(line.has_value());
  EXPECT_EQ(line->options.batch.solver, refine::BatchSolver::kRtr);
  EXPECT_EQ(line->options.batch.every, 7);
  EXPECT_TRUE(line->options.batch.reseed);
  EXPECT_EQ(line->options.journal_path, "/nonexistent/j/journal.lcmlog");
  for (const auto& row : refine::batchSolvers()) {
    if (row.refines) {
      EXPECT_EQ(parseServeCommandLine({"--batch", row.name})->options.batch.solver, row.solver);
      EXPECT_EQ(parseReplayCommandLine({"g.g2o", "--batch", row.name})->batch, row.solver);
    } else {
      EXPECT_THROW(parseServeCommandLine({"--batch", row.name}), UsageError) << row.name;
      EXPECT_THROW(parseReplayCommandLine({"g.g2o", "--batch", row.name}), UsageError) << row.name;
    }
  }
}

TEST(BatchSolverTable, EveryRowRoundTripsThroughParseAndToString) {
  std::set<std::string> names;
  for (const auto& row : refine::batchSolvers()) {
    EXPECT_EQ(refine::toString(row.solver), row.name);
    EXPECT_EQ(refine::parseBatchSolver(row.name), row.solver);
    EXPECT_EQ(&refine::info(row.solver), &row);
    EXPECT_TRUE(names.insert(row.name).second) << row.name << " twice";
    EXPECT_GT(std::string(row.description).size(), 10u) << row.name;
    // gn, lm and dogleg are core's BatchMethod under the same name; rtr is not one.
    const auto method = refine::batchMethod(row.solver);
    if (method) {
      EXPECT_EQ(toString(*method), row.name);
    } else {
      EXPECT_TRUE(row.certifies) << row.name;
    }
  }
  EXPECT_EQ(names, (std::set<std::string>{"gn", "lm", "dogleg", "rtr"}));
  EXPECT_EQ(refine::batchSolverNames(), "lm | gn | dogleg | rtr");
  EXPECT_EQ(refine::batchSolverNames(true), "lm | rtr");
}

TEST(BatchSolverTable, AnUnknownNameIsRefusedListingTheValidOnes) {
  try {
    refine::parseBatchSolver("newton", "--solver");
    FAIL() << "newton accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "--solver must be lm, gn, dogleg or rtr, not 'newton'");
  }
  try {
    refine::parseBatchSolver("gn", "--batch", /*refinement_only=*/true);
    FAIL() << "gn accepted as a refinement";
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "--batch must be lm or rtr, not 'gn'");
  }
}

// Every row runs through the one dispatch on a small noisy graph and lowers F from the
// odometry start; the certifying row says so.
TEST(BatchSolverTable, EveryRowRunsThroughTheDispatch) {
  sim::ManhattanOptions m;
  m.poses = 150;
  m.grid = 5;
  m.seed = 4;
  const PoseGraph<SE2> graph = sim::manhattanWorld(m).graph;
  const double F_start = objective(graph, graph.poses);
  for (const auto& row : refine::batchSolvers()) {
    std::vector<SE2> poses = graph.poses;
    const refine::BatchSolve s = refine::runBatchSolver(row.solver, graph, &poses);
    EXPECT_EQ(s.solver, row.solver);
    EXPECT_FALSE(s.diverged) << row.name << ": " << s.message;
    EXPECT_NEAR(s.F_final, objective(graph, poses), 1e-9 * s.F_final) << row.name;
    EXPECT_LT(s.F_final, F_start) << row.name;
    EXPECT_EQ(s.rtr.has_value(), row.certifies) << row.name;
    EXPECT_EQ(s.local.has_value(), refine::batchMethod(row.solver).has_value()) << row.name;
    if (row.certifies) {
      EXPECT_EQ(s.termination, "certified") << row.name;
    }
  }
}

// udpm's receive buffer: serve adds recv_buf_size to a udpm URL (its default, or --recv-buf),
// keeps a URL's own unless --recv-buf is given, and refuses --recv-buf on another provider or below
// 1 byte.
TEST(ServeCommandLine, RecvBufSizesTheUdpmReceiveBuffer) {
  const std::string base = "udpm://239.255.76.67:7700?ttl=0";
  auto line = parseServeCommandLine({"--lcm-url", base});
  EXPECT_EQ(line->url,
            base + "&recv_buf_size=" + std::to_string(ServeCommandLine::kDefaultRecvBufBytes));
  EXPECT_EQ(line->options.udpm_port, 7700);
  line = parseServeCommandLine({"--lcm-url", base, "--recv-buf", "65536"});
  EXPECT_EQ(line->url, base + "&recv_buf_size=65536");
  line = parseServeCommandLine({"--lcm-url", "udpm://239.255.76.67:7701?recv_buf_size=123"});
  EXPECT_EQ(line->url, "udpm://239.255.76.67:7701?recv_buf_size=123");  // the URL's own
  line = parseServeCommandLine(
      {"--lcm-url", "udpm://239.255.76.67:7701?recv_buf_size=123&ttl=0", "--recv-buf", "77"});
  EXPECT_EQ(line->url, "udpm://239.255.76.67:7701?recv_buf_size=77&ttl=0");  // the flag's
  line = parseServeCommandLine({"--lcm-url", "udpm://239.255.76.67", "--recv-buf", "9"});
  EXPECT_EQ(line->url, "udpm://239.255.76.67?recv_buf_size=9");
  EXPECT_EQ(line->options.udpm_port, 7667);
  line = parseServeCommandLine({"--lcm-url", "tcpq://127.0.0.1:7700"});
  EXPECT_EQ(line->url, "tcpq://127.0.0.1:7700");
  EXPECT_LE(line->options.udpm_port, 0);
  try {
    parseServeCommandLine({"--lcm-url", "tcpq://127.0.0.1:7700", "--recv-buf", "65536"});
    ADD_FAILURE() << "--recv-buf on tcpq accepted";
  } catch (const UsageError& e) {
    EXPECT_NE(std::string(e.what()).find("tcpq://127.0.0.1:7700"), std::string::npos) << e.what();
  }
  try {
    parseServeCommandLine({"--lcm-url", base, "--recv-buf=-5"});
    ADD_FAILURE() << "--recv-buf -5 accepted";
  } catch (const UsageError& e) {
    EXPECT_NE(std::string(e.what()).find("-5"), std::string::npos) << e.what();
  }
  EXPECT_THROW(serve::withReceiveBuffer("memq://", 100), std::invalid_argument);
  EXPECT_EQ(serve::udpmPort("memq://"), -1);
}

// Only whole flag names are taken: a prefix (`--thread` for `--threads`, `--out` for
// `--output`) is refused naming what was typed, in replay, serve and any other command, while the
// whole names and their `--flag=value` form still parse.
TEST(CommandLine, APrefixOfAFlagIsRefused) {
  const std::vector<std::vector<std::string>> prefixes = {
      {"--thread", "2"}, {"--out", "x.g2o"}, {"--relinearize-thresh", "0.1"}, {"--robus"}};
  for (const auto& prefix : prefixes) {
    std::vector<std::string> replay = {"graph.g2o"};
    replay.insert(replay.end(), prefix.begin(), prefix.end());
    for (const bool serve : {false, true}) {
      try {
        if (serve) {
          parseServeCommandLine(prefix);
        } else {
          parseReplayCommandLine(replay);
        }
        ADD_FAILURE() << (serve ? "serve " : "replay ") << prefix.front() << " accepted";
      } catch (const UsageError& e) {
        EXPECT_NE(std::string(e.what()).find(prefix.front()), std::string::npos) << e.what();
      }
    }
  }
  EXPECT_EQ(replaySmoother({"--threads", "2"}).threads, 2);
  EXPECT_EQ(serveSmoother({"--threads=2"}).threads, 2);
  boost::program_options::options_description any;
  any.add_options()("output", boost::program_options::value<std::string>(), "a file");
  EXPECT_THROW(parseArguments({"--out", "x"}, any, {}), UsageError);
  EXPECT_EQ(parseArguments({"--output", "x"}, any, {})["output"].as<std::string>(), "x");
}

}  // namespace
}  // namespace arbor::cli
