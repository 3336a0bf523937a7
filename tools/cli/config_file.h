// The file of `--config FILE` and `--print-config`: TOML's flat subset, one `key = value` a line
// (the key a flag's name without "--"), `#` comments, strings quoted ("..." or '...') or bare
// words, numbers, true and false; no tables.
#pragma once

#include <string>
#include <vector>

namespace arbor::cli {

struct ConfigEntry {
  std::string key;
  std::string value;  ///< as the command line would take it (quotes and escapes removed)
  int line = 0;
};

/// The entries of the file at `path`, in order. Throws UsageError "PATH:LINE: ..." on a line that
/// is not `key = value`, a table header, a bad string or a key given twice; "cannot read" when
/// the file cannot be opened.
std::vector<ConfigEntry> readConfigFile(const std::string& path);

/// `value` as a TOML value: bare when it is a number, true or false; otherwise a quoted string.
std::string tomlValue(const std::string& value);

}  // namespace arbor::cli
