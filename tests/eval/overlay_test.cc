// The overlay `secure render` draws into frames: where it draws, what colours say, the plot of h,
// determinism and its errors.
#include "secure/eval/overlay.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "tests/test_util.h"

namespace secure::eval {
namespace {

using test::ErrorOf;

constexpr int kW = 320, kH = 240;

domains::Frame Grey(int w = kW, int h = kH) {
  domains::Frame f;
  f.width = w;
  f.height = h;
  f.rgb.assign(3 * static_cast<std::size_t>(w) * h, 100);
  return f;
}

struct Px {
  int r, g, b;
};
Px At(const domains::Frame& f, int x, int y) {
  const std::size_t i = 3 * (static_cast<std::size_t>(y) * f.width + x);
  return {f.rgb[i], f.rgb[i + 1], f.rgb[i + 2]};
}
bool IsGrey(Px p) { return p.r == 100 && p.g == 100 && p.b == 100; }

// Pixels in rows [y0, y1) whose colour is that of the h curve (cyan: blue high, red low).
int CyanPixels(const domains::Frame& f, int y0, int y1) {
  int n = 0;
  for (int y = y0; y < y1; ++y)
    for (int x = 0; x < f.width; ++x) {
      const Px p = At(f, x, y);
      n += p.b > 180 && p.g > 140 && p.r < 130;
    }
  return n;
}

OverlayStep Step(long k, std::optional<double> h, std::string status = "safe",
                 bool intervened = false, bool collided = false) {
  OverlayStep s;
  s.step = k;
  s.h = h;
  s.status = std::move(status);
  s.intervened = intervened;
  s.collided = collided;
  return s;
}

TEST(OverlayTest, DrawsTheBandAndThePanelAndLeavesTheMiddleAlone) {
  EpisodeOverlay overlay({"SECURE, seed 0, episode 3", 100, true});
  domains::Frame f = Grey();
  overlay.Draw(Step(0, 0.5, ""), f);
  // The top band is darkened and carries text; the middle of the picture is untouched; the
  // panel at the bottom is darkened.
  EXPECT_LT(At(f, kW - 2, 2).r, 100);
  int bright = 0;
  for (int y = 0; y < 20; ++y)
    for (int x = 0; x < kW; ++x) bright += At(f, x, y).r > 200;
  EXPECT_GT(bright, 20) << "no text in the top band";
  EXPECT_TRUE(IsGrey(At(f, kW / 2, kH / 2)));
  EXPECT_LT(At(f, kW - 3, kH - 3).g, 100);
}

TEST(OverlayTest, BorderSaysInterventionOrangeAndCollisionRed) {
  EpisodeOverlay overlay({"", 100, false});
  domains::Frame plain = Grey(), intervened = Grey(), collided = Grey();
  overlay.Draw(Step(1, 0.2), plain);
  overlay.Draw(Step(2, 0.1, "safe_after_resampling", true), intervened);
  overlay.Draw(Step(3, -0.1, "safe", false, true), collided);
  // A pixel on the left edge, below the top band.
  const int y = kH / 2;
  EXPECT_TRUE(IsGrey(At(plain, 1, y)));
  const Px o = At(intervened, 1, y);
  EXPECT_GT(o.r, 200);
  EXPECT_GT(o.g, 90);
  EXPECT_LT(o.b, 80);
  const Px r = At(collided, 1, y);
  EXPECT_GT(r.r, 200);
  EXPECT_LT(r.g, 80);
  EXPECT_LT(r.b, 80);
  // Without a panel the bottom is untouched.
  EXPECT_TRUE(IsGrey(At(plain, kW / 2, kH - 3)));
}

TEST(OverlayTest, PanelPlotsHOnlyWhenItIsKnown) {
  const int panel_top = kH - kH / 4;
  EpisodeOverlay with_h({"", 50, true});
  domains::Frame f = Grey();
  for (long k = 0; k <= 20; ++k) {
    f = Grey();
    with_h.Draw(Step(k, std::sin(0.3 * k)), f);
  }
  EXPECT_GT(CyanPixels(f, panel_top, kH), 30);
  EXPECT_EQ(CyanPixels(f, 0, panel_top - 1), 0);

  EpisodeOverlay without_h({"", 50, true});
  for (long k = 0; k <= 20; ++k) {
    f = Grey();
    without_h.Draw(Step(k, std::nullopt, ""), f);
  }
  EXPECT_EQ(CyanPixels(f, 0, kH), 0);
}

TEST(OverlayTest, SameStepsSameBytesAndANewEpisodeClearsTheHistory) {
  auto run = [](EpisodeOverlay& overlay, int first, int last) {
    domains::Frame f;
    for (int k = first; k <= last; ++k) {
      f = Grey();
      overlay.Draw(Step(k, 0.1 * k - 0.5, "safe", k % 3 == 0), f);
    }
    return f.rgb;
  };
  EpisodeOverlay a({"x", 40, true}), b({"x", 40, true});
  const auto first = run(a, 0, 12);
  EXPECT_EQ(first, run(b, 0, 12));
  // a starts again at step 0 (a new episode): its frames are those of a fresh overlay.
  EpisodeOverlay fresh({"x", 40, true});
  EXPECT_EQ(run(a, 0, 5), run(fresh, 0, 5));
  EXPECT_NE(run(b, 0, 5), first);
}

TEST(OverlayTest, RejectsBadFramesAndValues) {
  EpisodeOverlay overlay;
  domains::Frame tiny = Grey(32, 24);
  EXPECT_HAS(ErrorOf([&] { overlay.Draw(Step(0, 0.0), tiny); }), "32 x 24");
  domains::Frame short_buffer = Grey();
  short_buffer.rgb.resize(10);
  EXPECT_HAS(ErrorOf([&] { overlay.Draw(Step(0, 0.0), short_buffer); }), "10 bytes");
  domains::Frame f = Grey();
  const domains::Frame before = f;
  EXPECT_HAS(ErrorOf([&] {
              overlay.Draw(Step(1, std::numeric_limits<double>::quiet_NaN()), f);
            }), "must be finite");
  EXPECT_EQ(f.rgb, before.rgb);  // an error draws nothing
  EXPECT_HAS(ErrorOf([] { EpisodeOverlay({"", -1, true}); }), "max_steps = -1");
}

}  // namespace
}  // namespace secure::eval
