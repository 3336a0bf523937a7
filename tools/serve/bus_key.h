// The deployment key of an authenticated bus (docs/lcm.md, "An authenticated bus"): a key file
// holds one or two 32-byte secrets, 64 hex digits a line ('#' starts a comment). The first key
// signs; every key in the file verifies, so a file with the current and the next key lets
// nodes be re-keyed one at a time. A key's id is derived from it (BLAKE2b), never chosen.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace arbor::serve {

struct BusKey {
  std::array<std::uint8_t, 32> secret{};
  std::uint64_t id = 0;  ///< the first 8 bytes of BLAKE2b("arbor bus key id" || secret)
};

/// The keys of one key file, the signing key first. Empty: no key (the bus is not authenticated).
using BusKeyring = std::vector<BusKey>;

/// At most this many keys in one file (the current and the next).
inline constexpr std::size_t kMaxBusKeys = 2;

/// A key's id as 16 hex digits (how logs, keygen and the docs name it).
std::string busKeyIdText(std::uint64_t id);

/// The key made of `secret` (its id computed).
BusKey busKeyFromSecret(const std::array<std::uint8_t, 32>& secret);

/// Reads a key file. Throws std::runtime_error naming the file and what is wrong: missing, not a
/// regular file, readable or writable by other users or writable by the group (chmod 600), a
/// line that is not 64 hex digits (named by its line number, the secret never echoed), no key,
/// more than kMaxBusKeys, a key twice.
BusKeyring readBusKeyFile(const std::string& path);

/// The text of a key file holding `keys`, the signing key first.
std::string busKeyFileText(const BusKeyring& keys);

/// Writes a new key file with one fresh random key (libsodium's randombytes), mode 0600, never
/// over an existing file. Returns the key. Throws std::runtime_error naming the file.
BusKey writeNewBusKeyFile(const std::string& path);

}  // namespace arbor::serve
