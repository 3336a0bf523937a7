// Options as data: one table per options struct (SmootherOptions, RobustOptions, ...), each row
// an option's name, tier, help section, value placeholder, help, the switch it needs, and how to
// read and set it as text. The command line (tools/cli/flag_set.h), --help's groups and
// --print-config come from the table; nothing here depends on a command-line library.
#pragma once

#include <cmath>
#include <functional>
#include <limits>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace arbor::cli {

/// Who an option is for: common (in --help), advanced and experimental (only in --help-all;
/// experimental ones exist for the project's own comparisons).
enum class Tier { kCommon, kAdvanced, kExperimental };

/// The kind of value an option takes.
enum class OptionType { kSwitch, kInteger, kReal, kWord };

/// One option of an options struct O.
template <class O>
struct OptionSpec {
  std::string name;  ///< the flag without "--", and the config file's key
  OptionType type = OptionType::kWord;
  Tier tier = Tier::kCommon;
  std::string section;  ///< the --help group it is listed under
  std::string arg;      ///< the value's placeholder ("N", "inline|async"); empty: a switch
  std::string help;
  std::string needs;    ///< the switch this option needs ("robust"), or empty
  std::string keyword;  ///< the Python module's keyword for it, or empty: none
  /// The value in `o` as the command line writes it; nullopt: it has none of its own (an
  /// option that sets others).
  std::function<std::optional<std::string>(const O&)> get;
  /// Sets the value from text; throws std::invalid_argument with the rest of the sentence
  /// "--NAME must be ..., not 'TEXT'" on a value the option refuses.
  std::function<void(O&, const std::string&)> set;
};

template <class O>
using OptionTable = std::vector<OptionSpec<O>>;

/// A condition on a number: its text for the error message ("> 0") and its test.
struct Condition {
  const char* text;
  bool (*holds)(double);
};

namespace option_detail {

// A value as a user would type it: 10, 0.1, 1e-06; a real in the fewest digits that read back
// as it (so that --print-config's file gives the same options).
template <class T>
std::string text(T value) {
  std::ostringstream out;
  if constexpr (std::is_floating_point_v<T>) {
    for (int digits = 6; digits < 17; ++digits) {
      out.str("");
      out.precision(digits);
      out << value;
      if (static_cast<T>(std::stod(out.str())) == value) return out.str();
    }
    out.str("");
    out.precision(17);
  }
  out << value;
  return out.str();
}

// `text` as a whole number or a real; throws invalid_argument "must be WHAT, not 'TEXT'".
template <class T>
T parseNumber(const std::string& text, const char* what) {
  const auto bad = [&] {
    return std::invalid_argument(std::string("must be ") + what + ", not '" + text + "'");
  };
  std::size_t used = 0;
  try {
    if constexpr (std::is_integral_v<T>) {
      // Whole numbers are read exactly (a seed past 2^53 keeps every digit), in T's range.
      if constexpr (std::is_unsigned_v<T>) {
        if (text.find('-') != std::string::npos) throw bad();
        const unsigned long long value = std::stoull(text, &used);
        if (used != text.size() || value > std::numeric_limits<T>::max()) throw bad();
        return static_cast<T>(value);
      } else {
        const long long value = std::stoll(text, &used);
        if (used != text.size() || value < std::numeric_limits<T>::min() ||
            value > std::numeric_limits<T>::max())
          throw bad();
        return static_cast<T>(value);
      }
    } else {
      const double value = std::stod(text, &used);
      if (used != text.size()) throw bad();
      return static_cast<T>(value);
    }
  } catch (const std::invalid_argument&) {
    throw bad();
  } catch (const std::out_of_range&) {
    throw bad();
  }
}

// A row without its get and set.
template <class O>
OptionSpec<O> spec(std::string name, OptionType type, Tier tier, std::string section,
                   std::string arg, std::string help, std::string needs) {
  OptionSpec<O> out;
  out.name = std::move(name);
  out.type = type;
  out.tier = tier;
  out.section = std::move(section);
  out.arg = std::move(arg);
  out.help = std::move(help);
  out.needs = std::move(needs);
  return out;
}

}  // namespace option_detail

/// A number at `access(o)` (a generic lambda returning a reference into O), refused unless
/// `condition` holds: "--NAME must be >= 1, not '0'".
template <class O, class Access>
OptionSpec<O> numberOption(std::string name, Tier tier, std::string section, std::string arg,
                           std::string help, Access access, Condition condition,
                           std::string needs = "") {
  using T = std::decay_t<decltype(access(std::declval<O&>()))>;
  OptionSpec<O> spec = option_detail::spec<O>(
      std::move(name), std::is_integral_v<T> ? OptionType::kInteger : OptionType::kReal, tier,
      std::move(section), std::move(arg), std::move(help), std::move(needs));
  spec.get = [access](const O& o) -> std::optional<std::string> {
    return option_detail::text(access(o));
  };
  spec.set = [access, condition](O& o, const std::string& text) {
    const T value =
        option_detail::parseNumber<T>(text, std::is_integral_v<T> ? "a whole number" : "a number");
    if (!condition.holds(static_cast<double>(value)))
      throw std::invalid_argument(std::string("must be ") + condition.text + ", not '" + text +
                                  "'");
    access(o) = value;
  };
  return spec;
}

/// A switch: given, it sets `access(o)` to `on`.
template <class O, class Access>
OptionSpec<O> switchOption(std::string name, Tier tier, std::string section, std::string help,
                           Access access, bool on) {
  OptionSpec<O> spec = option_detail::spec<O>(std::move(name), OptionType::kSwitch, tier,
                                              std::move(section), "", std::move(help), "");
  spec.get = [access, on](const O& o) -> std::optional<std::string> {
    return access(o) == on ? "true" : "false";
  };
  spec.set = [access, on](O& o, const std::string& text) {
    if (text != "true" && text != "false")
      throw std::invalid_argument("must be true or false, not '" + text + "'");
    access(o) = text == "true" ? on : !on;
  };
  return spec;
}

/// A value named by a word: `parse` (throwing std::invalid_argument with the rest of the
/// sentence) and `name` its inverse.
template <class O, class Access, class Parse, class Name>
OptionSpec<O> wordOption(std::string name, Tier tier, std::string section, std::string arg,
                         std::string help, Access access, Parse parse, Name word,
                         std::string needs = "") {
  OptionSpec<O> spec =
      option_detail::spec<O>(std::move(name), OptionType::kWord, tier, std::move(section),
                             std::move(arg), std::move(help), std::move(needs));
  spec.get = [access, word](const O& o) -> std::optional<std::string> {
    return std::string(word(access(o)));
  };
  spec.set = [access, parse](O& o, const std::string& text) { access(o) = parse(text); };
  return spec;
}

/// Text taken as given (a path, a URL, a prefix) at `access(o)`, a std::string; empty: no
/// value of its own (--help shows no default).
template <class O, class Access>
OptionSpec<O> textOption(std::string name, Tier tier, std::string section, std::string arg,
                         std::string help, Access access, std::string needs = "") {
  OptionSpec<O> spec =
      option_detail::spec<O>(std::move(name), OptionType::kWord, tier, std::move(section),
                             std::move(arg), std::move(help), std::move(needs));
  spec.get = [access](const O& o) -> std::optional<std::string> {
    const std::string& value = access(o);
    if (value.empty()) return std::nullopt;
    return value;
  };
  spec.set = [access](O& o, const std::string& text) { access(o) = text; };
  return spec;
}

/// `spec` with a Python keyword: `keyword`, or its name with '_' for '-' when empty.
template <class O>
OptionSpec<O> inPython(OptionSpec<O> spec, std::string keyword = "") {
  if (keyword.empty()) {
    keyword = spec.name;
    for (char& c : keyword)
      if (c == '-') c = '_';
  }
  spec.keyword = std::move(keyword);
  return spec;
}

/// A parse function for wordOption over two words, `first` naming `a` and `second` naming `b`:
/// "must be FIRST or SECOND, not 'TEXT'" on any other.
template <class T>
std::function<T(const std::string&)> eitherOf(std::string first, T a, std::string second, T b) {
  return [=](const std::string& text) {
    if (text == first) return a;
    if (text == second) return b;
    throw std::invalid_argument("must be " + first + " or " + second + ", not '" + text + "'");
  };
}

}  // namespace arbor::cli
