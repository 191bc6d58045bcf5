// The swarf CLI's subcommands. Each takes its arguments after the subcommand
// name and returns the process exit code; errors go to stderr.
#ifndef SWARF_CLIENT_COMMANDS_H_
#define SWARF_CLIENT_COMMANDS_H_

#include <string>
#include <vector>

namespace swarf::cli {

int TableCommand(const std::vector<std::string>& args);
int RunCommand(const std::vector<std::string>& args);
int LoadCommand(const std::vector<std::string>& args);
int HealthCommand(const std::vector<std::string>& args);
int SessionsCommand(const std::vector<std::string>& args);
int MarksCommand(const std::vector<std::string>& args);
int ViewCommand(const std::vector<std::string>& args);
int MovesCommand(const std::vector<std::string>& args);

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_COMMANDS_H_
