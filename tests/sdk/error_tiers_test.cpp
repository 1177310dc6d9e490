// The error tiers (softshell/result.h, assert.h, log.h): one translation of exceptions, a
// replaceable assert handler, and internal errors reported to the SDK log sink.
#include <gtest/gtest.h>

#include <mutex>
#include <stdexcept>
#include <string>
#include <vector>

#include "softshell/assert.h"
#include "softshell/log.h"
#include "softshell/result.h"

namespace softshell {
namespace {

struct CapturedLog {
  std::mutex mu;
  std::vector<std::string> lines;
};

// Installs a sink that records the SDK's messages for the test's duration.
class ErrorTiers : public ::testing::Test {
 protected:
  void SetUp() override {
    set_log_sink([log = &log_](LogLevel, std::string_view m) {
      std::lock_guard lock(log->mu);
      log->lines.emplace_back(m);
    });
  }
  void TearDown() override { set_log_sink({}); }
  CapturedLog log_;
};

TEST_F(ErrorTiers, CaptureTranslatesEveryKindOfException) {
  const Result<int> fine = capture([] { return 7; });
  ASSERT_TRUE(fine.ok());
  EXPECT_EQ(*fine, 7);
  const Result<int> passed_on = capture([]() -> Result<int> { return Error{ErrorCode::kNotFound, "no such thing"}; });
  EXPECT_EQ(passed_on.error().code, ErrorCode::kNotFound);
  const Result<void> thrown = capture([] { fail(ErrorCode::kUnprocessable, "cannot"); });
  EXPECT_EQ(thrown.error().code, ErrorCode::kUnprocessable);
  EXPECT_EQ(thrown.error().message, "cannot");
  const Result<void> memory = capture([] { throw std::bad_alloc(); }, "decoding the body");
  EXPECT_EQ(memory.error().code, ErrorCode::kResourceExhausted);
  EXPECT_EQ(memory.error().message, "out of memory while decoding the body");
  EXPECT_TRUE(log_.lines.empty()) << "input errors and exhaustion are not bugs: nothing is logged";

  const Result<void> bug = capture([] { throw std::logic_error("index mix-up"); }, "solving");
  EXPECT_EQ(bug.error().code, ErrorCode::kInternal);
  EXPECT_EQ(bug.error().message, "internal error while solving: index mix-up");
  const Result<void> unknown = capture([] { throw 42; });
  EXPECT_EQ(unknown.error().code, ErrorCode::kInternal);
  ASSERT_EQ(log_.lines.size(), 2u) << "internal errors are reported to the SDK sink";
  EXPECT_EQ(log_.lines[0], "internal error while solving: index mix-up");
}

TEST_F(ErrorTiers, FailedAssertionsBecomeInternalErrorsByDefault) {
  const Result<void> r = capture([] { SOFTSHELL_ASSERT(1 + 1 == 3, "arithmetic is off by " + std::to_string(1)); });
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::kInternal);
  EXPECT_NE(r.error().message.find("arithmetic is off by 1"), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("1 + 1 == 3"), std::string::npos) << r.error().message;
  EXPECT_NE(r.error().message.find("error_tiers_test.cpp"), std::string::npos) << r.error().message;
  EXPECT_EQ(log_.lines.size(), 1u);
}

std::vector<std::string>* g_recorded = nullptr;

TEST_F(ErrorTiers, TheAssertHandlerIsReplaceable) {
  std::vector<std::string> recorded;
  g_recorded = &recorded;
  const AssertHandler previous = set_assert_handler(+[](const char* expression, const std::string& message, const char*, int) {
    g_recorded->push_back(std::string(expression) + ": " + message);
  });
  EXPECT_EQ(previous, nullptr);
  bool continued = false;
  SOFTSHELL_ASSERT(false, std::string("recorded, not thrown"));
  continued = true;
  EXPECT_TRUE(continued);
  ASSERT_EQ(recorded.size(), 1u);
  EXPECT_EQ(recorded[0], "false: recorded, not thrown");
  SOFTSHELL_ASSERT(true, std::string("never evaluated"));
  EXPECT_EQ(recorded.size(), 1u);
  set_assert_handler(nullptr);
  g_recorded = nullptr;
  EXPECT_FALSE(capture([] { SOFTSHELL_ASSERT(false, std::string("default again")); }).ok());
}

TEST(LogLevels, ParseAndName) {
  EXPECT_EQ(parse_log_level("WARN").value(), LogLevel::kWarning);
  EXPECT_EQ(to_string(LogLevel::kError), "error");
  EXPECT_FALSE(parse_log_level("loud").ok());
  const Logger quiet{LogLevel::kError, [](LogLevel, std::string_view) { FAIL() << "below the threshold"; }};
  quiet.warning("dropped");
}

}  // namespace
}  // namespace softshell
