#include "arbor_slam/tools/serve/bus_key.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include <fcntl.h>
#include <sodium.h>
#include <sys/stat.h>
#include <unistd.h>

namespace arbor::serve {
namespace {

void initSodium() {
  if (sodium_init() < 0) throw std::runtime_error("libsodium could not be initialised");
}

int hexDigit(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

std::string trimmed(const std::string& line) {
  const std::size_t hash = line.find('#');
  std::string s = line.substr(0, hash);
  const std::size_t first = s.find_first_not_of(" \t\r");
  if (first == std::string::npos) return "";
  const std::size_t last = s.find_last_not_of(" \t\r");
  return s.substr(first, last - first + 1);
}

std::string modeText(mode_t mode) {
  char text[8];
  std::snprintf(text, sizeof text, "%04o", static_cast<unsigned>(mode & 07777));
  return text;
}

}  // namespace

std::string busKeyIdText(std::uint64_t id) {
  char text[17];
  std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(id));
  return text;
}

BusKey busKeyFromSecret(const std::array<std::uint8_t, 32>& secret) {
  initSodium();
  static const char kLabel[] = "arbor bus key id";
  std::uint8_t input[sizeof kLabel - 1 + 32];
  std::memcpy(input, kLabel, sizeof kLabel - 1);
  std::memcpy(input + sizeof kLabel - 1, secret.data(), secret.size());
  std::uint8_t digest[8];
  crypto_generichash(digest, sizeof digest, input, sizeof input, nullptr, 0);
  sodium_memzero(input, sizeof input);
  BusKey key;
  key.secret = secret;
  for (std::uint8_t b : digest) key.id = key.id << 8 | b;
  return key;
}

BusKeyring readBusKeyFile(const std::string& path) {
  const std::string where = "key file " + path;
  struct stat st;
  if (::stat(path.c_str(), &st) != 0) {
    throw std::runtime_error(where + ": " + std::strerror(errno));
  }
  if (!S_ISREG(st.st_mode)) throw std::runtime_error(where + ": not a regular file");
  if ((st.st_mode & 0027) != 0) {
    throw std::runtime_error(where + ": mode " + modeText(st.st_mode) +
                             " lets other users read or change the key; chmod 600 " + path);
  }
  std::ifstream in(path);
  if (!in) throw std::runtime_error(where + ": cannot be read");
  BusKeyring keys;
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    const std::string text = trimmed(line);
    if (text.empty()) continue;
    const std::string at = where + ", line " + std::to_string(number);
    if (text.size() != 64) {
      throw std::runtime_error(at + ": a key is 64 hex digits, not " + std::to_string(text.size()) +
                               " characters");
    }
    std::array<std::uint8_t, 32> secret{};
    for (std::size_t i = 0; i < 32; ++i) {
      const int hi = hexDigit(text[2 * i]), lo = hexDigit(text[2 * i + 1]);
      if (hi < 0 || lo < 0) throw std::runtime_error(at + ": not a hex digit in the key");
      secret[i] = static_cast<std::uint8_t>(hi << 4 | lo);
    }
    const BusKey key = busKeyFromSecret(secret);
    sodium_memzero(secret.data(), secret.size());
    for (const BusKey& k : keys) {
      if (k.id == key.id) throw std::runtime_error(at + ": key " + busKeyIdText(key.id) + " twice");
    }
    keys.push_back(key);
    if (keys.size() > kMaxBusKeys) {
      throw std::runtime_error(at + ": more than " + std::to_string(kMaxBusKeys) +
                               " keys (the current and the next)");
    }
  }
  sodium_memzero(line.data(), line.size());
  if (keys.empty()) throw std::runtime_error(where + ": no key in it");
  return keys;
}

std::string busKeyFileText(const BusKeyring& keys) {
  std::ostringstream out;
  static const char* kHex = "0123456789abcdef";
  for (std::size_t k = 0; k < keys.size(); ++k) {
    out << "# arbor bus key " << busKeyIdText(keys[k].id) << (k == 0 ? " (signs)" : " (verifies)")
        << "\n";
    for (std::uint8_t b : keys[k].secret) out << kHex[b >> 4] << kHex[b & 15];
    out << "\n";
  }
  return out.str();
}

BusKey writeNewBusKeyFile(const std::string& path) {
  initSodium();
  std::array<std::uint8_t, 32> secret{};
  randombytes_buf(secret.data(), secret.size());
  const BusKey key = busKeyFromSecret(secret);
  sodium_memzero(secret.data(), secret.size());
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
  if (fd < 0) throw std::runtime_error("key file " + path + ": " + std::strerror(errno));
  std::string text = busKeyFileText({key});
  const bool written = ::write(fd, text.data(), text.size()) == static_cast<ssize_t>(text.size());
  sodium_memzero(text.data(), text.size());
  const bool closed = ::close(fd) == 0;
  if (!written || !closed) {
    ::unlink(path.c_str());
    throw std::runtime_error("key file " + path + ": could not be written");
  }
  return key;
}

}  // namespace arbor::serve
