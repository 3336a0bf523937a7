// Splitting a text line into whitespace-separated fields and parsing them as numbers or ids.
// Internal to io/.
#pragma once

#include <cstdint>
#include <istream>
#include <string>
#include <string_view>
#include <vector>

#include "arbor_slam/io/pose_graph_file.h"

namespace arbor::io_detail {

/// The fields of `line` separated by spaces, tabs, CR, VT or FF; a '#' starts a comment.
void splitFields(std::string_view line, std::vector<std::string_view>* fields);

/// Parses a finite double (an optional leading '+' is allowed). Returns nullptr on success,
/// else why the token is not acceptable ("is not a number", "is not finite", …).
const char* parseNumber(std::string_view token, double* value);

/// Parses a non-negative decimal integer id. Returns nullptr on success, else why not.
const char* parseId(std::string_view token, std::int64_t* id);

/// The loop of a line-per-record file: visit(fields, number, where) for each line of `in` with
/// a field (number: from 1; where: "NAME:NUMBER: ", the start of a message about that line),
/// then FileError on a read error.
template <class Visit>
void forEachFieldLine(std::istream& in, const std::string& name, Visit&& visit) {
  std::vector<std::string_view> fields;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    splitFields(line, &fields);
    if (fields.empty()) continue;
    visit(fields, number, name + ":" + std::to_string(number) + ": ");
  }
  if (in.bad()) throw FileError(name + ": read error");
}

}  // namespace arbor::io_detail
