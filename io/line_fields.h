// Splitting a text line into whitespace-separated fields and parsing them as numbers or ids.
// Internal to io/.
#pragma once

#include <cstdint>
#include <string_view>
#include <vector>

namespace arbor::io_detail {

/// The fields of `line` separated by spaces, tabs, CR, VT or FF; a '#' starts a comment.
void splitFields(std::string_view line, std::vector<std::string_view>* fields);

/// Parses a finite double (an optional leading '+' is allowed). Returns nullptr on success,
/// else why the token is not acceptable ("is not a number", "is not finite", …).
const char* parseNumber(std::string_view token, double* value);

/// Parses a non-negative decimal integer id. Returns nullptr on success, else why not.
const char* parseId(std::string_view token, std::int64_t* id);

}  // namespace arbor::io_detail
