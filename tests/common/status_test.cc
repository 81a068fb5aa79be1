// Status and Expected: values, errors with and without a reason code, and the checked misuse.
#include "m2s/common/status.h"

#include <memory>
#include <set>
#include <string>

#include <gtest/gtest.h>

namespace m2s {
namespace {

Expected<int> Parse(const std::string& text) {
  if (text.empty()) return Expected<int>::Error(DropReason::kBadBytes, "empty input");
  if (text == "x") return Expected<int>::Error("not a number");
  return static_cast<int>(text.size());
}

TEST(Status, OkAndErrors) {
  EXPECT_TRUE(Status::Ok());
  EXPECT_FALSE(Status::Ok().reason().has_value());
  const Status plain = Status::Error("disk full");
  EXPECT_FALSE(plain);
  EXPECT_EQ(plain.message(), "disk full");
  EXPECT_FALSE(plain.reason().has_value());
  const Status coded = Status::Error(DropReason::kOutOfImage, "feature outside the image");
  EXPECT_EQ(coded.reason(), DropReason::kOutOfImage);
  EXPECT_EQ(coded.Prefixed("frame 3: ").message(), "frame 3: feature outside the image");
  EXPECT_EQ(coded.Prefixed("frame 3: ").reason(), DropReason::kOutOfImage);
  EXPECT_TRUE(Status::Ok().Prefixed("never shown: "));
  EXPECT_EQ(Status::Ok().Prefixed("never shown: ").message(), "");
}

TEST(Expected, ValueOrErrorWithItsReason) {
  const Expected<int> three = Parse("abc");
  ASSERT_TRUE(three);
  EXPECT_EQ(*three, 3);
  EXPECT_EQ(three.error(), "");
  EXPECT_TRUE(three.status());

  const Expected<int> empty = Parse("");
  ASSERT_FALSE(empty);
  EXPECT_EQ(empty.reason(), DropReason::kBadBytes);
  EXPECT_EQ(empty.error(), "empty input");
  EXPECT_EQ(empty.status().reason(), DropReason::kBadBytes);

  const Expected<int> word = Parse("x");
  EXPECT_EQ(word.error(), "not a number");
  EXPECT_FALSE(word.status().reason().has_value());

  // Move-only values move out.
  Expected<std::unique_ptr<int>> owned = std::make_unique<int>(7);
  std::unique_ptr<int> taken = std::move(owned).value();
  EXPECT_EQ(*taken, 7);
}

TEST(DropReason, EveryReasonHasItsOwnName) {
  std::set<std::string> names;
  for (int r = 0; r < kNumDropReasons; ++r) {
    const std::string name = ToString(static_cast<DropReason>(r));
    EXPECT_NE(name, "unknown") << r;
    EXPECT_TRUE(names.insert(name).second) << name << " twice";
  }
  EXPECT_STREQ(ToString(DropReason::kCount), "unknown");
}

using StatusDeathTest = ::testing::Test;

// An Expected holds a value or an error; built from an OK status it would hold neither.
TEST_F(StatusDeathTest, ExpectedRefusesAnOkStatus) {
  EXPECT_DEATH(Expected<int>{Status::Ok()}, "needs a value or an error");
  EXPECT_DEATH((void)Parse("x").reason(), "uncoded error");
  EXPECT_DEATH((void)Parse("abc").reason(), "reason\\(\\) of a value");
}

}  // namespace
}  // namespace m2s
