// The `arbor` subcommands. Each takes its arguments (after the subcommand name) and returns
// the process exit code; argument errors are thrown as UsageError.
#pragma once

#include <string>
#include <vector>

namespace arbor::cli {

int batchCommand(const std::vector<std::string>& args);
int generateCommand(const std::vector<std::string>& args);
int benchCommand(const std::vector<std::string>& args);
int replayCommand(const std::vector<std::string>& args);
int serveCommand(const std::vector<std::string>& args);
int publishCommand(const std::vector<std::string>& args);
int spyCommand(const std::vector<std::string>& args);
/// `arbor plot ESTIMATE [REFERENCE]`: a PNG of the trajectory, ATE and RPE against a reference.
int plotCommand(const std::vector<std::string>& args);
int commandCommand(const std::vector<std::string>& args);
/// `arbor command covariance ID [ID2]` (commandCommand hands it over).
int covarianceCommand(const std::vector<std::string>& args);
/// `arbor keygen FILE`: a new deployment key for the authenticated bus (tools/cli/bus_key_flag.h).
int keygenCommand(const std::vector<std::string>& args);

}  // namespace arbor::cli
