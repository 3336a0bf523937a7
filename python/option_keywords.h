// Python keywords from the options tables (tools/cli/option_table.h): a row with a `keyword` is
// taken by that name, checked by the row's own rule, readable back, and named in the docstring.
#pragma once

#include <algorithm>
#include <stdexcept>
#include <string>

#include <pybind11/pybind11.h>

#include "arbor_slam/tools/cli/option_table.h"

namespace arbor::python {

namespace py = pybind11;

/// The row whose keyword is `keyword`, or nullptr.
template <class O>
const cli::OptionSpec<O>* rowOf(const cli::OptionTable<O>& table, const std::string& keyword) {
  const auto row = std::find_if(table.begin(), table.end(), [&](const cli::OptionSpec<O>& r) {
    return !r.keyword.empty() && r.keyword == keyword;
  });
  return row == table.end() ? nullptr : &*row;
}

/// Sets the option of the keyword `name` in `options` from `value`. TypeError "OWNER: unexpected
/// keyword 'NAME'" or "OWNER: NAME must be an int, not float"; ValueError "OWNER: NAME must be
/// ..., not 'VALUE'" on a value the row refuses.
template <class O>
void setKeyword(const cli::OptionTable<O>& table, const std::string& owner, const std::string& name,
                const py::handle& value, O* options) {
  const cli::OptionSpec<O>* row = rowOf(table, name);
  if (!row) throw py::type_error(owner + ": unexpected keyword '" + name + "'");
  auto refuse = [&](const char* type) {
    return py::type_error(owner + ": " + name + " must be " + type + ", not " +
                          std::string(py::str(value.get_type().attr("__name__"))));
  };
  std::string text;
  try {
    switch (row->type) {
      case cli::OptionType::kInteger:
        try {
          text = std::to_string(value.cast<int>());
        } catch (const py::cast_error&) {
          throw refuse("an int");
        }
        break;
      case cli::OptionType::kReal:
        text = cli::option_detail::text(value.cast<double>());
        break;
      case cli::OptionType::kSwitch:
        text = value.cast<bool>() ? "true" : "false";
        break;
      case cli::OptionType::kWord:
        text = value.cast<std::string>();
        break;
    }
  } catch (const py::cast_error&) {
    throw refuse(row->type == cli::OptionType::kWord ? "a str" : "a number");
  }
  try {
    row->set(*options, text);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(owner + ": " + name + " " + e.what());
  }
}

/// The value of a row in `options` as Python's type: an int, a float, a bool or a str.
template <class O>
py::object keywordValue(const cli::OptionSpec<O>& row, const O& options) {
  const std::string text = row.get(options).value_or("");
  switch (row.type) {
    case cli::OptionType::kInteger:
      return py::int_(std::stoi(text));
    case cli::OptionType::kReal:
      return py::float_(std::stod(text));
    case cli::OptionType::kSwitch:
      return py::bool_(text == "true");
    case cli::OptionType::kWord:
      break;
  }
  return py::str(text);
}

/// "threads (an int, default 0), dogleg (a bool, default False), ...": the keywords of `table`
/// with their types and defaults, for a docstring.
template <class O>
std::string keywordsDoc(const cli::OptionTable<O>& table, const O& defaults = {}) {
  std::string text;
  for (const cli::OptionSpec<O>& row : table) {
    if (row.keyword.empty()) continue;
    const std::string value = row.get(defaults).value_or("");
    std::string kind;
    switch (row.type) {
      case cli::OptionType::kInteger:
        kind = "an int, default " + value;
        break;
      case cli::OptionType::kReal:
        kind = "a number, default " + value;
        break;
      case cli::OptionType::kSwitch:
        kind = std::string("a bool, default ") + (value == "true" ? "True" : "False");
        break;
      case cli::OptionType::kWord:
        kind = row.arg + ", default " + value;
        break;
    }
    text += (text.empty() ? "" : ", ") + row.keyword + " (" + kind + ")";
  }
  return text;
}

}  // namespace arbor::python
