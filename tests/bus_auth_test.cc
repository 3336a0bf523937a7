// The authenticated bus's envelope and key files (tools/serve/bus_auth.h, bus_key.h) alone:
// a sealed message opens to its bytes; unsigned, wrong-key, tampered (every byte), wrong-channel,
// replayed, too old and old-epoch messages are refused by reason; rotation with a current and a
// next key; key files made, read and refused with the reason.
#include <array>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <sys/stat.h>

#include "process_temp_dir.h"

#include "arbor_slam/tools/serve/bus_auth.h"
#include "arbor_slam/tools/serve/bus_key.h"

namespace arbor::serve {
namespace {

constexpr std::int64_t kNow = 1'800'000'000'000'000;  // µs: a fixed clock for the tests

BusKey keyOf(std::uint8_t fill) {
  std::array<std::uint8_t, 32> secret{};
  for (std::size_t i = 0; i < secret.size(); ++i) secret[i] = static_cast<std::uint8_t>(fill + i);
  return busKeyFromSecret(secret);
}

const std::vector<std::uint8_t> kMessage = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12};

OpenedMessage openAt(BusAuth& auth, const std::string& channel,
                     const std::vector<std::uint8_t>& bytes, std::int64_t now = kNow) {
  return auth.open(channel, bytes.data(), bytes.size(), now);
}

std::vector<std::uint8_t> sealAt(BusAuth& auth, const std::string& channel,
                                 std::int64_t now = kNow) {
  return auth.seal(channel, kMessage.data(), kMessage.size(), now);
}

TEST(BusAuth, ASealedMessageOpensToItsBytes) {
  BusAuth sender({keyOf(1)}), receiver({keyOf(1)});
  const std::vector<std::uint8_t> sealed = sealAt(sender, "ARBOR_EDGES");
  EXPECT_EQ(sealed.size(), kMessage.size() + kEnvelopeOverhead);
  const OpenedMessage m = openAt(receiver, "ARBOR_EDGES", sealed);
  ASSERT_EQ(m.problem, AuthProblem::kNone) << m.detail;
  EXPECT_EQ(std::vector<std::uint8_t>(m.data, m.data + m.size), kMessage);
  EXPECT_EQ(m.sender, sender.sender());
}

TEST(BusAuth, AnUnsignedMessageIsRefused) {
  BusAuth receiver({keyOf(1)});
  EXPECT_EQ(openAt(receiver, "ARBOR_EDGES", kMessage).problem, AuthProblem::kUnsigned);
  EXPECT_EQ(openAt(receiver, "ARBOR_EDGES", {}).problem, AuthProblem::kUnsigned);
  std::vector<std::uint8_t> long_plain(500, 7);
  const OpenedMessage m = openAt(receiver, "ARBOR_EDGES", long_plain);
  EXPECT_EQ(m.problem, AuthProblem::kUnsigned);
  EXPECT_NE(m.detail.find("500 bytes on ARBOR_EDGES"), std::string::npos) << m.detail;
}

TEST(BusAuth, AnotherKeyIsRefusedAsUnknown) {
  BusAuth sender({keyOf(2)}), receiver({keyOf(1)});
  const OpenedMessage m = openAt(receiver, "ARBOR_EDGES", sealAt(sender, "ARBOR_EDGES"));
  EXPECT_EQ(m.problem, AuthProblem::kUnknownKey);
  EXPECT_NE(m.detail.find(busKeyIdText(keyOf(2).id)), std::string::npos) << m.detail;
}

TEST(BusAuth, EveryFlippedByteIsRefused) {
  BusAuth sender({keyOf(1)});
  const std::vector<std::uint8_t> sealed = sealAt(sender, "ARBOR_EDGES");
  for (std::size_t i = 0; i < sealed.size(); ++i) {
    for (std::uint8_t bit : {0x01, 0x80}) {
      BusAuth receiver({keyOf(1)});  // a fresh window: only the flip can refuse it
      std::vector<std::uint8_t> tampered = sealed;
      tampered[i] ^= bit;
      const AuthProblem p = openAt(receiver, "ARBOR_EDGES", tampered).problem;
      // The magic's bytes make it unsigned, the key id's an unknown key, the rest the MAC.
      const AuthProblem expected = i < 4    ? AuthProblem::kUnsigned
                                   : i < 12 ? AuthProblem::kUnknownKey
                                            : AuthProblem::kMac;
      EXPECT_EQ(p, expected) << "byte " << i << " bit " << int(bit);
    }
  }
}

TEST(BusAuth, AMessageMovedToAnotherChannelIsRefused) {
  BusAuth sender({keyOf(1)}), receiver({keyOf(1)});
  const std::vector<std::uint8_t> sealed = sealAt(sender, "ARBOR_PRIORS");
  EXPECT_EQ(openAt(receiver, "ARBOR_EDGES", sealed).problem, AuthProblem::kMac);
  EXPECT_EQ(openAt(receiver, "ARBOR_PRIORS", sealed).problem, AuthProblem::kNone);
}

TEST(BusAuth, AReplayIsRefusedAndReorderingInsideTheWindowIsNot) {
  BusAuth sender({keyOf(1)}), receiver({keyOf(1)});
  std::vector<std::vector<std::uint8_t>> sealed;
  for (std::uint64_t k = 0; k < kReplayWindow + 10; ++k) sealed.push_back(sealAt(sender, "C"));
  ASSERT_EQ(openAt(receiver, "C", sealed[5]).problem, AuthProblem::kNone);
  EXPECT_EQ(openAt(receiver, "C", sealed[5]).problem, AuthProblem::kReplay);
  EXPECT_EQ(openAt(receiver, "C", sealed[0]).problem, AuthProblem::kNone);  // late, once
  EXPECT_EQ(openAt(receiver, "C", sealed[0]).problem, AuthProblem::kReplay);
  // Counter 1034 (the last): 1 .. 10 fall out of the window, 11 and up stay in it.
  ASSERT_EQ(openAt(receiver, "C", sealed.back()).problem, AuthProblem::kNone);
  EXPECT_EQ(openAt(receiver, "C", sealed[9]).problem, AuthProblem::kReplay);
  EXPECT_EQ(openAt(receiver, "C", sealed[10]).problem, AuthProblem::kNone);
  EXPECT_EQ(openAt(receiver, "C", sealed[10]).problem, AuthProblem::kReplay);
  EXPECT_EQ(openAt(receiver, "C", sealed.back()).problem, AuthProblem::kReplay);
}

TEST(BusAuth, AnOlderEpochIsRefusedAndANewerOneStartsAfresh) {
  BusAuthOptions first;
  first.sender = 42;
  first.epoch = 100;
  BusAuthOptions restarted = first;
  restarted.epoch = 200;
  BusAuth before({keyOf(1)}, first), after({keyOf(1)}, restarted), receiver({keyOf(1)});
  const std::vector<std::uint8_t> old_message = sealAt(before, "C");
  ASSERT_EQ(openAt(receiver, "C", sealAt(before, "C")).problem, AuthProblem::kNone);
  ASSERT_EQ(openAt(receiver, "C", sealAt(after, "C")).problem, AuthProblem::kNone);  // counter 1
  EXPECT_EQ(openAt(receiver, "C", old_message).problem, AuthProblem::kReplay);
  EXPECT_EQ(openAt(receiver, "C", sealAt(after, "C")).problem, AuthProblem::kNone);
}

TEST(BusAuth, AMessageOutsideTheClockWindowIsRefused) {
  BusAuth sender({keyOf(1)}), receiver({keyOf(1)});
  const std::int64_t window = BusAuthOptions{}.clock_window_us;
  const OpenedMessage old = openAt(receiver, "C", sealAt(sender, "C", kNow - window - 1));
  EXPECT_EQ(old.problem, AuthProblem::kClock);
  EXPECT_NE(old.detail.find("before"), std::string::npos) << old.detail;
  EXPECT_EQ(openAt(receiver, "C", sealAt(sender, "C", kNow + window + 1)).problem,
            AuthProblem::kClock);
  EXPECT_EQ(openAt(receiver, "C", sealAt(sender, "C", kNow - window)).problem, AuthProblem::kNone);
  // Any time the sender writes, however far off, is refused without overflowing.
  for (std::int64_t t : {std::numeric_limits<std::int64_t>::min(),
                         std::numeric_limits<std::int64_t>::max(), std::int64_t{0}}) {
    EXPECT_EQ(openAt(receiver, "C", sealAt(sender, "C", t)).problem, AuthProblem::kClock) << t;
  }
}

TEST(BusAuth, RotationWithACurrentAndANextKey) {
  const BusKey current = keyOf(1), next = keyOf(2);
  BusAuth old_node({current}), staged({current, next}), rotated({next, current}), new_node({next});
  // Step 1: nodes with {current, next} still sign with current: old nodes accept them.
  EXPECT_EQ(openAt(old_node, "C", sealAt(staged, "C")).problem, AuthProblem::kNone);
  // Step 2: nodes that sign with next are accepted by staged nodes, not by old ones.
  EXPECT_EQ(openAt(staged, "C", sealAt(rotated, "C")).problem, AuthProblem::kNone);
  EXPECT_EQ(openAt(old_node, "C", sealAt(rotated, "C")).problem, AuthProblem::kUnknownKey);
  EXPECT_EQ(openAt(rotated, "C", sealAt(old_node, "C")).problem, AuthProblem::kNone);
  // Step 3: the retired key is refused.
  EXPECT_EQ(openAt(new_node, "C", sealAt(rotated, "C")).problem, AuthProblem::kNone);
  EXPECT_EQ(openAt(new_node, "C", sealAt(old_node, "C")).problem, AuthProblem::kUnknownKey);
  EXPECT_EQ(rotated.signingKeyId(), next.id);
}

TEST(BusAuth, NewKeysTakeEffectAtOnceAndTheReplayWindowsStay) {
  const BusKey current = keyOf(1), next = keyOf(2);
  BusAuth old_sender({current}), new_sender({next}), receiver({current});
  const std::vector<std::uint8_t> seen = sealAt(old_sender, "C");
  ASSERT_EQ(openAt(receiver, "C", seen).problem, AuthProblem::kNone);
  EXPECT_EQ(openAt(receiver, "C", sealAt(new_sender, "C")).problem, AuthProblem::kUnknownKey);
  receiver.setKeys({next, current});
  EXPECT_EQ(receiver.signingKeyId(), next.id);
  EXPECT_EQ(openAt(receiver, "C", sealAt(new_sender, "C")).problem, AuthProblem::kNone);
  EXPECT_EQ(openAt(receiver, "C", seen).problem, AuthProblem::kReplay);
  receiver.setKeys({next});
  EXPECT_EQ(openAt(receiver, "C", sealAt(old_sender, "C")).problem, AuthProblem::kUnknownKey);
  EXPECT_THROW(receiver.setKeys({}), std::invalid_argument);
  EXPECT_EQ(openAt(receiver, "C", sealAt(new_sender, "C")).problem, AuthProblem::kNone);
}

class BusKeyFile : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ =
        arbor::testing::processTempDir() /
        ("bus_key_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string write(const std::string& name, const std::string& text, mode_t mode = 0600) {
    const std::string path = (dir_ / name).string();
    std::ofstream(path) << text;
    ::chmod(path.c_str(), mode);
    return path;
  }
  static std::string errorOf(const std::string& path) {
    try {
      readBusKeyFile(path);
    } catch (const std::runtime_error& e) {
      return e.what();
    }
    return "";
  }
  std::filesystem::path dir_;
};

TEST_F(BusKeyFile, KeygenWritesAPrivateFileThatReadsBack) {
  const std::string path = (dir_ / "bus.key").string();
  const BusKey made = writeNewBusKeyFile(path);
  struct stat st;
  ASSERT_EQ(::stat(path.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  const BusKeyring read = readBusKeyFile(path);
  ASSERT_EQ(read.size(), 1u);
  EXPECT_EQ(read[0].id, made.id);
  EXPECT_EQ(read[0].secret, made.secret);
  EXPECT_NE(writeNewBusKeyFile((dir_ / "other.key").string()).id, made.id);
  EXPECT_THROW(writeNewBusKeyFile(path), std::runtime_error);  // never over a file
  EXPECT_EQ(readBusKeyFile(path)[0].secret, made.secret);
}

TEST_F(BusKeyFile, TwoKeysTheFirstSigns) {
  const std::string path = write("ring.key", busKeyFileText({keyOf(2), keyOf(1)}));
  const BusKeyring read = readBusKeyFile(path);
  ASSERT_EQ(read.size(), 2u);
  EXPECT_EQ(read[0].id, keyOf(2).id);
  EXPECT_EQ(read[1].id, keyOf(1).id);
}

TEST_F(BusKeyFile, BadFilesAreRefusedWithTheReason) {
  const std::string text = busKeyFileText({keyOf(1)});
  const std::string world = write("world.key", text, 0644);
  EXPECT_NE(errorOf(world).find("mode 0644"), std::string::npos) << errorOf(world);
  EXPECT_NE(errorOf(world).find("chmod 600 " + world), std::string::npos);
  EXPECT_NE(errorOf(write("group.key", text, 0620)).find("mode 0620"), std::string::npos);
  EXPECT_EQ(errorOf(write("group_read.key", text, 0640)), "");  // a service group may read it
  EXPECT_NE(errorOf((dir_ / "absent.key").string()).find("No such file"), std::string::npos);
  EXPECT_NE(errorOf(dir_.string()).find("not a regular file"), std::string::npos);
  EXPECT_NE(errorOf(write("empty.key", "# nothing\n\n")).find("no key"), std::string::npos);
  const std::string short_key = errorOf(write("short.key", "# a key\nabcd\n"));
  EXPECT_NE(short_key.find("line 2: a key is 64 hex digits, not 4"), std::string::npos)
      << short_key;
  std::string bad = text.substr(text.find('\n') + 1);
  bad[10] = 'x';
  const std::string not_hex = errorOf(write("hex.key", bad));
  EXPECT_NE(not_hex.find("line 1: not a hex digit"), std::string::npos) << not_hex;
  EXPECT_EQ(not_hex.find(bad.substr(0, 10)), std::string::npos) << "never echo the secret";
  EXPECT_NE(errorOf(write("three.key", busKeyFileText({keyOf(1), keyOf(2), keyOf(3)})))
                .find("more than 2 keys"),
            std::string::npos);
  EXPECT_NE(errorOf(write("twice.key", busKeyFileText({keyOf(1), keyOf(1)}))).find("twice"),
            std::string::npos);
}

}  // namespace
}  // namespace arbor::serve
