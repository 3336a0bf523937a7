// printf-style formatting of one number for the benchmark tables.
#pragma once

#include <cstdio>
#include <string>

namespace arbor::bench {

/// `value` formatted by the printf format `format` (one double conversion), e.g. "%.3f".
inline std::string fmt(const char* format, double value) {
  char buf[64];
  std::snprintf(buf, sizeof buf, format, value);
  return buf;
}

}  // namespace arbor::bench
