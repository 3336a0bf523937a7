#include "arbor_slam/tools/cli/config_file.h"

#include <cctype>
#include <fstream>
#include <set>

#include "arbor_slam/tools/cli/cli_common.h"

namespace arbor::cli {

namespace {

std::string trimmed(const std::string& text) {
  const auto first = text.find_first_not_of(" \t\r");
  if (first == std::string::npos) return "";
  return text.substr(first, text.find_last_not_of(" \t\r") - first + 1);
}

bool isKey(const std::string& key) {
  if (key.empty()) return false;
  for (char c : key)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_') return false;
  return true;
}

// The value after '=' (comment included): its text, or a reason it is malformed in `error`.
std::string valueOf(const std::string& rest, std::string* error) {
  const std::string text = trimmed(rest);
  if (text.empty()) {
    *error = "a value after '='";
    return "";
  }
  const char quote = text[0];
  if (quote == '"' || quote == '\'') {
    std::string value;
    std::size_t k = 1;
    for (; k < text.size() && text[k] != quote; ++k) {
      if (quote == '"' && text[k] == '\\' && k + 1 < text.size()) {
        const char e = text[++k];
        value += e == 'n' ? '\n' : e == 't' ? '\t' : e;
      } else {
        value += text[k];
      }
    }
    const std::string after = k < text.size() ? trimmed(text.substr(k + 1)) : "";
    if (k >= text.size() || (!after.empty() && after[0] != '#'))
      *error = "a string closed by " + std::string(1, quote) + " and nothing after it";
    return value;
  }
  const std::string bare = trimmed(text.substr(0, text.find('#')));
  if (bare.find_first_of(" \t") != std::string::npos)
    *error = "one word or a quoted string, not '" + bare + "'";
  return bare;
}

}  // namespace

std::vector<ConfigEntry> readConfigFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw UsageError("--config: cannot read '" + path + "'");
  std::vector<ConfigEntry> entries;
  std::set<std::string> seen;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    const std::string text = trimmed(line);
    if (text.empty() || text[0] == '#') continue;
    const std::string where = path + ":" + std::to_string(number) + ": ";
    if (text[0] == '[')
      throw UsageError(where + "tables are not read; give every option as `key = value`");
    const auto equals = text.find('=');
    const std::string key = trimmed(text.substr(0, equals));
    if (equals == std::string::npos || !isKey(key))
      throw UsageError(where + "expected `key = value`, not '" + text + "'");
    std::string error;
    const std::string value = valueOf(text.substr(equals + 1), &error);
    if (!error.empty()) throw UsageError(where + key + ": expected " + error);
    if (!seen.insert(key).second) throw UsageError(where + key + " is given twice");
    entries.push_back({key, value, number});
  }
  return entries;
}

std::string tomlValue(const std::string& value) {
  if (value == "true" || value == "false") return value;
  std::size_t used = 0;
  try {
    std::stod(value, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  const bool number =
      used > 0 && used == value.size() && value.find_first_of("xXpP") == std::string::npos &&
      value.find("inf") == std::string::npos && value.find("nan") == std::string::npos;
  if (number) return value;
  std::string out = "\"";
  for (char c : value) {
    if (c == '"' || c == '\\') out += '\\';
    if (c == '\n') {
      out += "\\n";
      continue;
    }
    out += c;
  }
  return out + "\"";
}

}  // namespace arbor::cli
