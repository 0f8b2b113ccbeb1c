// ProgressLine (secure/common/progress.h): the live line on a terminal, milestones only elsewhere.
#include "secure/common/progress.h"

#include <gtest/gtest.h>

#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace secure {
namespace {

// The text after the last '\r' of `s` (what a terminal shows on the current line).
std::string Shown(const std::string& s) { return s.substr(s.rfind('\r') + 1); }

TEST(ProgressLineTest, NotLivePrintsOnlyTheMilestonesAsGiven) {
  std::ostringstream out;
  {
    ProgressLine line(&out, /*live=*/false, /*min_redraw_seconds=*/0.0);
    line.Start(10, "experiment");
    line.Advance(3);
    line.Milestone("[seed 0] AIRL iteration 1/4: rollout success 0.5");
    line.Advance(7);
    line.Milestone("[seed 0] evaluated: bc 50%/0%");
    line.Finish();
    EXPECT_EQ(line.done(), 10);
    EXPECT_EQ(line.total(), 10);
  }
  EXPECT_EQ(out.str(),
            "[seed 0] AIRL iteration 1/4: rollout success 0.5\n[seed 0] evaluated: bc 50%/0%\n");
}

TEST(ProgressLineTest, LiveLineShowsDoneTotalElapsedAndTimeLeftAndIsClearedAtTheEnd) {
  std::ostringstream out;
  ProgressLine line(&out, /*live=*/true, /*min_redraw_seconds=*/0.0);
  line.Start(4, "experiment");
  EXPECT_EQ(Shown(out.str()).rfind("experiment: 0/4 (0%), ", 0), 0u) << out.str();
  EXPECT_NE(Shown(out.str()).find(" elapsed, --:-- left"), std::string::npos) << out.str();
  line.Advance();
  const std::string shown = Shown(out.str());
  EXPECT_EQ(shown.rfind("experiment: 1/4 (25%), ", 0), 0u) << shown;
  EXPECT_NE(shown.find(" elapsed, ~"), std::string::npos) << shown;
  EXPECT_NE(shown.find(" left"), std::string::npos) << shown;
  EXPECT_EQ(out.str().find('\n'), std::string::npos);  // redrawn in place

  // A milestone clears the line, prints itself, and the live line comes back below it.
  line.Milestone("[seed 0] barrier (baseline): done");
  const std::string text = out.str();
  const std::size_t newline = text.find("[seed 0] barrier (baseline): done\n");
  ASSERT_NE(newline, std::string::npos) << text;
  EXPECT_EQ(text[newline - 1], '\r');  // the live line was wiped first
  EXPECT_EQ(Shown(text).rfind("experiment: 1/4", 0), 0u) << text;

  line.Advance(3);
  EXPECT_EQ(Shown(out.str()).rfind("experiment: 4/4 (100%), ", 0), 0u) << out.str();
  line.Finish();
  // Cleared: the last line drawn is overwritten by blanks, and the cursor is back at its start.
  const std::string text_after = out.str();
  const std::string last_drawn = text_after.substr(0, text_after.rfind('\r'));
  ASSERT_EQ(text_after.back(), '\r');
  const std::size_t blank_start = last_drawn.rfind('\r') + 1;
  const std::string blank = last_drawn.substr(blank_start);
  EXPECT_EQ(blank.find_first_not_of(' '), std::string::npos) << text_after;
  const std::string before_blank = last_drawn.substr(0, blank_start - 1);
  EXPECT_GE(blank.size(), Shown(before_blank).size());
  EXPECT_EQ(Shown(before_blank).rfind("experiment: 4/4", 0), 0u) << text_after;
  // Nothing more is drawn until the next Start.
  const std::size_t size = out.str().size();
  line.Advance();
  EXPECT_EQ(out.str().size(), size);
}

TEST(ProgressLineTest, ALiveLineWithoutAStreamPrintsNothing) {
  ProgressLine line(nullptr, /*live=*/true);
  EXPECT_FALSE(line.live());
  line.Start(2, "x");
  line.Milestone("m");
  line.Advance(2);
  line.Finish();
  EXPECT_EQ(line.done(), 2);
}

TEST(ProgressLineTest, UnitsDoneBeforeStartCountButNotTowardsTheEstimate) {
  // A resumed run: 6 of 10 done before; the estimate needs a unit done in this run.
  EXPECT_EQ(ProgressLine::Format("AIRL iterations", 6, 10, 5.0, 0),
            "AIRL iterations: 6/10 (60%), 0:05 elapsed, --:-- left");
  EXPECT_EQ(ProgressLine::Format("AIRL iterations", 8, 10, 20.0, 2),
            "AIRL iterations: 8/10 (80%), 0:20 elapsed, ~0:20 left");
  std::ostringstream out;
  ProgressLine line(&out, true, 0.0);
  line.Start(10, "AIRL iterations", 6);
  EXPECT_EQ(Shown(out.str()).rfind("AIRL iterations: 6/10 (60%)", 0), 0u) << out.str();
  EXPECT_EQ(line.done(), 6);
}

TEST(ProgressLineTest, FormatsDurationsAndTheEstimateFromTheAverageTimePerUnit) {
  EXPECT_EQ(ProgressLine::Duration(0.4), "0:00");
  EXPECT_EQ(ProgressLine::Duration(75), "1:15");
  EXPECT_EQ(ProgressLine::Duration(3725), "1:02:05");
  // 3 units in 30 s: 10 s each, 7 left.
  EXPECT_EQ(ProgressLine::Format("experiment", 3, 10, 30.0, 3),
            "experiment: 3/10 (30%), 0:30 elapsed, ~1:10 left");
  EXPECT_EQ(ProgressLine::Format("experiment", 0, 0, 0.0, 0),
            "experiment: 0/0, 0:00 elapsed, --:-- left");
}

TEST(ProgressLineTest, ThreadsAdvanceOneSharedCount) {
  std::ostringstream out;
  ProgressLine line(&out, /*live=*/true);  // the default redraw interval
  line.Start(4 * 250, "experiment");
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&line, t] {
      for (int i = 0; i < 250; ++i) {
        line.Advance();
        if (i % 50 == 0) line.Milestone("[seed " + std::to_string(t) + "] step");
      }
    });
  }
  for (std::thread& t : threads) t.join();
  EXPECT_EQ(line.done(), 1000);
  line.Finish();
  // Every milestone is a whole line of its own (after the '\r' that wiped the live line).
  std::istringstream lines(out.str());
  std::string l;
  int milestones = 0;
  while (std::getline(lines, l)) {
    if (lines.eof()) break;  // the cleared rest
    const std::string text = Shown(l);
    EXPECT_TRUE(text.size() == 13 && text.rfind("[seed ", 0) == 0 && text.find("] step") == 7)
        << text;
    ++milestones;
  }
  EXPECT_EQ(milestones, 4 * 5);
}

TEST(ProgressLineTest, ModesAndStatusLines) {
  EXPECT_TRUE(ProgressLine::Live(ProgressMode::kAlways));
  EXPECT_FALSE(ProgressLine::Live(ProgressMode::kNever));
  EXPECT_EQ(FromString(kProgressModeNames, "always", "--progress"), ProgressMode::kAlways);
  EXPECT_THROW(FromString(kProgressModeNames, "sometimes", "--progress"), Error);

  // A status line of a trainer goes above the installed live line.
  std::ostringstream out;
  {
    ProgressLine line(&out, true, 0.0);
    line.Install();
    line.Start(3, "AIRL iterations");
    PrintStatusLineF("[airl] it %d/%d\n", 1, 3);
  }
  EXPECT_NE(out.str().find("\r[airl] it 1/3\n"), std::string::npos) << out.str();
  EXPECT_EQ(out.str().back(), '\r');  // cleared by the destructor
}

}  // namespace
}  // namespace secure
