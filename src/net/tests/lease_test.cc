#include "teachsim/net/lease.h"

#include <gtest/gtest.h>

#include <random>

namespace teachsim::net {
namespace {

TEST(Lease, OneHolderAtATimeOthersReadOnly) {
  LeaseManager lease;
  EXPECT_FALSE(lease.holder().has_value());
  EXPECT_FALSE(lease.CheckCommand(1).ok());
  ASSERT_TRUE(lease.Request(1).ok());
  EXPECT_TRUE(lease.Request(1).ok());  // asking again is harmless
  Status refused = lease.Request(2);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.message(), "the controller lease is held by session 1");
  EXPECT_TRUE(lease.CheckCommand(1).ok());
  EXPECT_EQ(lease.CheckCommand(2).message(), "read-only: the controller lease is held by session 1");
  EXPECT_FALSE(lease.Release(2).ok());  // only the holder releases
  EXPECT_EQ(lease.holder(), 1u);
  ASSERT_TRUE(lease.Release(1).ok());
  ASSERT_TRUE(lease.Request(2).ok());
  EXPECT_EQ(lease.holder(), 2u);
}

TEST(Lease, DisconnectReleasesOnlyTheHolder) {
  LeaseManager lease;
  ASSERT_TRUE(lease.Request(4).ok());
  std::uint64_t generation = lease.generation();
  EXPECT_FALSE(lease.OnDisconnect(5));
  EXPECT_EQ(lease.generation(), generation);
  EXPECT_TRUE(lease.OnDisconnect(4));
  EXPECT_FALSE(lease.holder().has_value());
  EXPECT_GT(lease.generation(), generation);
  EXPECT_TRUE(lease.Request(5).ok());
}

TEST(Lease, RandomSequencesNeverGiveTwoHolders) {
  // Property: whatever the order of requests, releases and disconnects, at most one session may
  // command, and it is the holder.
  std::mt19937 rng(7);
  LeaseManager lease;
  for (int step = 0; step < 5000; ++step) {
    SessionId s = 1 + rng() % 4;
    switch (rng() % 3) {
      case 0: (void)lease.Request(s); break;
      case 1: (void)lease.Release(s); break;
      case 2: lease.OnDisconnect(s); break;
    }
    int may_command = 0;
    for (SessionId t = 1; t <= 4; ++t) {
      if (lease.CheckCommand(t).ok()) {
        ++may_command;
        EXPECT_EQ(lease.holder(), t);
      }
    }
    EXPECT_EQ(may_command, lease.holder() ? 1 : 0);
  }
}

}  // namespace
}  // namespace teachsim::net
