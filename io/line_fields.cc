#include "arbor_slam/io/line_fields.h"

#include <charconv>
#include <cmath>
#include <system_error>

namespace arbor::io_detail {

namespace {
bool isBlank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }
}  // namespace

void splitFields(std::string_view line, std::vector<std::string_view>* fields) {
  fields->clear();
  const std::size_t hash = line.find('#');
  if (hash != std::string_view::npos) line = line.substr(0, hash);
  std::size_t k = 0;
  while (k < line.size()) {
    while (k < line.size() && isBlank(line[k])) ++k;
    const std::size_t start = k;
    while (k < line.size() && !isBlank(line[k])) ++k;
    if (k > start) fields->push_back(line.substr(start, k - start));
  }
}

const char* parseNumber(std::string_view token, double* value) {
  const char* first = token.data();
  const char* last = first + token.size();
  if (first != last && *first == '+') {
    ++first;  // std::from_chars rejects a leading '+'
    if (first != last && (*first == '+' || *first == '-')) return "is not a number";
  }
  if (first == last) return "is not a number";
  const auto [ptr, ec] = std::from_chars(first, last, *value, std::chars_format::general);
  if (ec == std::errc::result_out_of_range) return "is out of the range of a double";
  if (ec != std::errc() || ptr != last) return "is not a number";
  if (!std::isfinite(*value)) return "is not finite";
  return nullptr;
}

const char* parseId(std::string_view token, std::int64_t* id) {
  const char* first = token.data();
  const char* last = first + token.size();
  const auto [ptr, ec] = std::from_chars(first, last, *id);
  if (ec == std::errc::result_out_of_range) return "is out of the range of an id";
  if (ec != std::errc() || ptr != last) return "is not a non-negative integer id";
  if (*id < 0) return "is a negative id";
  return nullptr;
}

}  // namespace arbor::io_detail
