// Minimal per-subcommand option parsing: --name value, --name=value, --flag.
#ifndef SWARF_CLIENT_ARGS_H_
#define SWARF_CLIENT_ARGS_H_

#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace swarf::cli {

class Args {
 public:
  // `valued`: options that take a value; `flags`: options that don't.
  // InvalidArgument naming an unknown option or a missing value.
  static absl::StatusOr<Args> Parse(const std::vector<std::string>& argv,
                                    const std::set<std::string>& valued,
                                    const std::set<std::string>& flags);

  bool Has(const std::string& name) const { return values_.count(name) > 0; }
  // All values given for an option, in order (options may repeat).
  std::vector<std::string> All(const std::string& name) const;
  std::optional<std::string> Get(const std::string& name) const;
  // Integer option; InvalidArgument naming the option if not an integer.
  absl::StatusOr<std::optional<int>> GetInt(const std::string& name) const;
  const std::vector<std::string>& positional() const { return positional_; }

 private:
  std::multimap<std::string, std::string> values_;
  std::vector<std::string> positional_;
};

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_ARGS_H_
