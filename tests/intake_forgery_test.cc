// The intake rules against one forged message (issue 56 item 3), without LCM: a seq jump is
// held until the sender's next messages confirm it, the sender tables evict the least recently
// heard sender instead of refusing a new one, gap counts saturate, a fixed dimension never moves.
#include <cstdint>
#include <limits>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/io/lcm_messages.h"
#include "arbor_slam/tests/lcm_test_support.h"
#include "arbor_slam/tools/serve/edge_intake.h"

namespace arbor::serve {
namespace {

using testing::edgeBytes;
using testing::streamEdge;

constexpr std::int64_t kMax = std::numeric_limits<std::int64_t>::max();

class Forgery : public ::testing::Test {
 protected:
  PoseGraph2 graph = testing::manhattanGraph(40, 4, -1, 3);
  IntakeResult admit(EdgeIntake& intake, std::int64_t seq, std::int64_t sender = 1, int e = 0) {
    const auto b = edgeBytes(streamEdge(graph, e, seq, sender));
    return intake.admit(b.data(), static_cast<int>(b.size()));
  }
};

TEST_F(Forgery, AJumpBeyondTheLimitIsHeldAndTheRealStreamIsAllAccepted) {
  EdgeIntake intake;
  const IntakeResult forged = admit(intake, std::int64_t{1} << 62);
  EXPECT_EQ(forged.verdict, Intake::kHeld);
  EXPECT_EQ(intake.counts().held, 1);
  EXPECT_EQ(intake.counts().gaps, 0);
  for (std::int64_t seq = 1; seq <= 100; ++seq) {
    const IntakeResult r = admit(intake, seq);
    ASSERT_EQ(r.verdict, Intake::kAccepted) << seq << " " << r.detail;
    EXPECT_EQ(r.dropped, seq == 1 ? 1 : 0);  // the sender speaking in its window drops it
  }
  const IntakeCounts& c = intake.counts();
  EXPECT_EQ(c.accepted, 100);
  EXPECT_EQ(c.held, 0);
  EXPECT_EQ(c.gaps, 0);
  EXPECT_EQ(c.jumps_confirmed, 0);
  EXPECT_EQ(c.rejected_by_reason.at("unconfirmed jump"), 1);
}

TEST_F(Forgery, AJumpWithinTheLimitMovesAtOnce) {
  EdgeIntake intake;
  ASSERT_EQ(admit(intake, 1).verdict, Intake::kAccepted);
  const IntakeResult r = admit(intake, 1 + intake.jumpLimit());
  EXPECT_EQ(r.verdict, Intake::kAccepted);
  EXPECT_EQ(r.skipped, intake.jumpLimit() - 1);
  EXPECT_EQ(admit(intake, 2 + intake.jumpLimit() + intake.jumpLimit()).verdict, Intake::kHeld);
}

TEST_F(Forgery, ARunOfConsecutiveSeqsConfirmsTheJumpInAnyOrder) {
  EdgeIntake intake(0, 16);  // jump limit 15
  ASSERT_EQ(intake.jumpLimit(), 15);
  for (std::int64_t seq = 1; seq <= 3; ++seq)
    ASSERT_EQ(admit(intake, seq).verdict, Intake::kAccepted);
  EXPECT_EQ(admit(intake, 5000).verdict, Intake::kHeld);
  EXPECT_EQ(admit(intake, 5000).verdict, Intake::kDuplicate);  // held: still a duplicate
  EXPECT_EQ(admit(intake, 5000, 1, 1).reason, "seq reused");
  EXPECT_EQ(admit(intake, 5002).verdict, Intake::kHeld);
  const IntakeResult r = admit(intake, 5001);
  ASSERT_EQ(r.verdict, Intake::kAccepted);
  ASSERT_EQ(r.released.size(), 2u);
  EXPECT_EQ(r.released[0].seq, 5000);
  EXPECT_EQ(r.released[1].seq, 5002);
  EXPECT_EQ(r.released[0].verdict, Intake::kAccepted);
  EXPECT_FALSE(r.released[0].wire.empty());  // the bytes, for the journal
  EXPECT_EQ(r.skipped, 4996);
  const IntakeCounts& c = intake.counts();
  EXPECT_EQ(c.accepted, 6);
  EXPECT_EQ(c.held, 0);
  EXPECT_EQ(c.jumps_confirmed, 1);
  EXPECT_EQ(c.gaps, 4996);
  // The window moved with the confirmed jump: what is below it is stale, what is held is known.
  EXPECT_EQ(admit(intake, 3).reason, "stale");
  EXPECT_EQ(admit(intake, 5001).verdict, Intake::kDuplicate);
  EXPECT_EQ(admit(intake, 5003).verdict, Intake::kAccepted);
}

TEST_F(Forgery, AJumpElsewhereOrTheSenderInItsWindowDropsWhatWasHeld) {
  EdgeIntake intake;
  EXPECT_EQ(admit(intake, 100000).verdict, Intake::kHeld);
  EXPECT_EQ(admit(intake, 100001).verdict, Intake::kHeld);
  const IntakeResult elsewhere = admit(intake, 900000);  // not 100002: a new run
  EXPECT_EQ(elsewhere.verdict, Intake::kHeld);
  EXPECT_EQ(elsewhere.dropped, 2);
  EXPECT_EQ(admit(intake, 900001).verdict, Intake::kHeld);
  EXPECT_EQ(admit(intake, 7).dropped, 2);                   // the sender itself, inside its window
  EXPECT_EQ(admit(intake, 900002).verdict, Intake::kHeld);  // starts over: not confirmed
  const IntakeCounts& c = intake.counts();
  EXPECT_EQ(c.rejected_by_reason.at("unconfirmed jump"), 4);
  EXPECT_EQ(c.held, 1);
  EXPECT_EQ(c.accepted, 1);
  EXPECT_EQ(c.received, c.accepted + c.rejected + c.held + c.duplicates);
}

TEST_F(Forgery, GapCountsSaturateInsteadOfOverflowing) {
  EdgeIntake intake;
  EXPECT_EQ(admit(intake, kMax).verdict, Intake::kHeld);  // alone: no gap at all
  EXPECT_EQ(intake.counts().gaps, 0);
  for (std::int64_t sender = 1; sender <= 3; ++sender) {
    for (std::int64_t k = 2; k >= 0; --k) admit(intake, kMax - k, sender + 10);
  }
  EXPECT_EQ(intake.counts().jumps_confirmed, 3);
  EXPECT_EQ(intake.counts().gaps, kMax);
  for (const auto& [sender, gaps] : intake.gapsBySender(EdgeIntake::Kind::kEdge)) {
    EXPECT_EQ(gaps, kMax - 3) << sender;
  }
  EXPECT_EQ(admit(intake, kMax - 1, 11).verdict, Intake::kDuplicate);
}

TEST_F(Forgery, ANewSenderTakesTheLeastRecentlyHeardTable) {
  EdgeIntake intake(0, EdgeIntake::kDefaultWindow, 4);
  for (std::int64_t sender = 1; sender <= 4; ++sender) admit(intake, 1, sender);
  admit(intake, 2, 1);  // sender 1 heard again: sender 2 is now the idlest
  const IntakeResult fifth = admit(intake, 1, 5);
  EXPECT_EQ(fifth.verdict, Intake::kAccepted);
  EXPECT_EQ(fifth.evicted, 2);
  EXPECT_EQ(intake.senders(EdgeIntake::Kind::kEdge), 4u);
  EXPECT_EQ(intake.counts().senders_evicted, 1);
  // A flood of invented senders never refuses the real one.
  for (std::int64_t sender = 100; sender < 164; ++sender) admit(intake, 1, sender);
  for (std::int64_t seq = 3; seq <= 50; ++seq) {
    ASSERT_EQ(admit(intake, seq, 1).verdict, Intake::kAccepted) << seq;
  }
  EXPECT_EQ(intake.senders(EdgeIntake::Kind::kEdge), 4u);
  EXPECT_EQ(intake.counts().rejected, 0);
  // An evicted sender that comes back beyond the jump limit must confirm its seq again.
  for (std::int64_t sender = 200; sender < 204; ++sender) admit(intake, 1, sender);
  EXPECT_EQ(admit(intake, 100000, 1).verdict, Intake::kHeld);
}

TEST_F(Forgery, AHeldMessageOfAnEvictedSenderIsDropped) {
  EdgeIntake intake(0, EdgeIntake::kDefaultWindow, 2);
  EXPECT_EQ(admit(intake, 100000, 1).verdict, Intake::kHeld);
  admit(intake, 1, 2);
  const IntakeResult third = admit(intake, 1, 3);
  EXPECT_EQ(third.evicted, 1);
  EXPECT_EQ(third.dropped, 1);
  EXPECT_EQ(intake.counts().held, 0);
}

TEST_F(Forgery, AFixedDimensionNeverMoves) {
  EdgeIntake intake(2);
  StreamEdge<SE3> e3;
  e3.sender = 1;
  e3.seq = 1;
  e3.from = 0;
  e3.to = 1;
  const auto b = encodeMessage(makeEdgeMessage(e3));
  EXPECT_EQ(intake.admit(b.data(), static_cast<int>(b.size())).reason, "dim");
  EXPECT_EQ(intake.dim(), 2);
  // Refused before its seq is looked at: the real seq 1 of sender 1 is still new.
  EXPECT_EQ(admit(intake, 1).verdict, Intake::kAccepted);
  EXPECT_EQ(intake.counts().rejected_by_reason.at("dim"), 1);
}

TEST_F(Forgery, AConfirmedJumpFixesAnOpenDimensionOnce) {
  EdgeIntake intake;  // no dimension yet
  for (std::int64_t seq = 100000; seq < 100000 + EdgeIntake::kConfirmRun; ++seq) {
    admit(intake, seq);
  }
  EXPECT_EQ(intake.counts().jumps_confirmed, 1);
  EXPECT_EQ(intake.dim(), 2);
}

TEST_F(Forgery, AnEdgeCommandBeyondTheLimitIsAcceptedButNeverMovesTheHighestSeq) {
  // `arbor command` numbers commands by the clock (ms): each one is a jump.
  EdgeIntake intake(2);
  auto admit = [&](std::int64_t seq, Key to = 9) {
    StreamEdgeCommand c;
    c.sender = 1;
    c.seq = seq;
    c.from = 4;
    c.to = to;
    const auto b = encodeMessage(makeEdgeCommandMessage(c));
    return intake.admitCommand(b.data(), static_cast<int>(b.size()));
  };
  EXPECT_EQ(admit(std::int64_t{1} << 62).verdict, Intake::kAccepted);  // forged
  const std::int64_t now_ms = 1796671434868;
  EXPECT_EQ(admit(now_ms).verdict, Intake::kAccepted);
  EXPECT_EQ(admit(now_ms).verdict, Intake::kDuplicate);
  EXPECT_EQ(admit(now_ms, 10).reason, "seq reused");
  EXPECT_EQ(admit(now_ms + 5000).verdict, Intake::kAccepted);
  EXPECT_EQ(admit(1).verdict, Intake::kAccepted);  // the window was never moved
  const IntakeResult late = admit(now_ms + 9000);
  intake.revoke(late, "journal");
  EXPECT_EQ(admit(now_ms + 9000).verdict, Intake::kAccepted);  // may be sent again
  // Only the last kRecentJumps are remembered: memory stays bounded.
  for (std::int64_t k = 0; k < 100; ++k) admit(now_ms + 10000 + k);
  EXPECT_EQ(admit(now_ms + 10099).verdict, Intake::kDuplicate);
  const IntakeCounts& c = intake.commandCounts();
  EXPECT_EQ(c.gaps, 0);  // jumped over, never skipped
  EXPECT_EQ(c.held, 0);
}

}  // namespace
}  // namespace arbor::serve
