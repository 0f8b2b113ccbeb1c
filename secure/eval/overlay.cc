#include "secure/eval/overlay.h"

#include <cairo.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>

#include "secure/common/error.h"

namespace secure::eval {
namespace {

struct Rgb {
  double r, g, b;
};
constexpr Rgb kWhite{1.0, 1.0, 1.0};
constexpr Rgb kGrey{0.7, 0.7, 0.7};
constexpr Rgb kGreen{0.35, 0.85, 0.55};
constexpr Rgb kYellow{0.95, 0.85, 0.3};
constexpr Rgb kOrange{1.0, 0.55, 0.15};
constexpr Rgb kRed{1.0, 0.2, 0.2};
constexpr Rgb kCyan{0.35, 0.8, 1.0};
constexpr const char* kFont = "DejaVu Sans Mono";

Rgb StatusColor(const std::string& status) {
  if (status.empty()) return kGrey;
  if (status == "safe") return kGreen;
  if (status == "safe_after_resampling") return kYellow;
  return kRed;  // no_safe_action, invalid_input
}

void SetColor(cairo_t* cr, const Rgb& c, double alpha = 1.0) {
  cairo_set_source_rgba(cr, c.r, c.g, c.b, alpha);
}

// Draws `text` at the current point in `color` and advances the current point past it.
void Text(cairo_t* cr, const std::string& text, const Rgb& color) {
  SetColor(cr, color);
  cairo_show_text(cr, text.c_str());
}

struct CairoDeleter {
  void operator()(cairo_t* cr) const { cairo_destroy(cr); }
  void operator()(cairo_surface_t* s) const { cairo_surface_destroy(s); }
};

std::string Signed(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%+.3f", v);
  return buf;
}

}  // namespace

void OverlayOptions::Validate() const {
  SECURE_CHECK(max_steps >= 0, "overlay: max_steps = " << max_steps << ", must be >= 0");
}

EpisodeOverlay::EpisodeOverlay(OverlayOptions options) : options_(std::move(options)) {
  options_.Validate();
}

void EpisodeOverlay::Draw(const OverlayStep& step, domains::Frame& frame) {
  const int w = frame.width, h = frame.height;
  SECURE_CHECK(w >= 64 && h >= 48, "overlay: the frame is " << w << " x " << h
                                                             << ", must be at least 64 x 48");
  SECURE_CHECK(frame.rgb.size() == 3 * static_cast<std::size_t>(w) * static_cast<std::size_t>(h),
               "overlay: a " << w << " x " << h << " frame has " << frame.rgb.size()
                             << " bytes, expected 3 * width * height");
  SECURE_CHECK(step.step >= 0, "overlay: step = " << step.step << ", must be >= 0");
  SECURE_CHECK(!step.h || std::isfinite(*step.h), "overlay: h = " << *step.h
                                                                  << " at step " << step.step
                                                                  << ", must be finite");
  if (!history_.empty() && step.step <= history_.back().step) history_.clear();
  history_.push_back({step.step, step.h, step.intervened, step.collided});

  // The frame into Cairo's xRGB words, and back after drawing.
  const int stride = cairo_format_stride_for_width(CAIRO_FORMAT_RGB24, w);
  SECURE_CHECK(stride == 4 * w, "overlay: unexpected Cairo stride " << stride);
  pixels_.resize(static_cast<std::size_t>(w) * h);
  for (std::size_t i = 0; i < pixels_.size(); ++i) {
    const std::uint8_t* p = &frame.rgb[3 * i];
    pixels_[i] = (std::uint32_t{p[0]} << 16) | (std::uint32_t{p[1]} << 8) | p[2];
  }
  std::unique_ptr<cairo_surface_t, CairoDeleter> surface(cairo_image_surface_create_for_data(
      reinterpret_cast<unsigned char*>(pixels_.data()), CAIRO_FORMAT_RGB24, w, h, stride));
  SECURE_CHECK(cairo_surface_status(surface.get()) == CAIRO_STATUS_SUCCESS,
               "overlay: Cairo: " << cairo_status_to_string(cairo_surface_status(surface.get())));
  std::unique_ptr<cairo_t, CairoDeleter> context(cairo_create(surface.get()));
  cairo_t* cr = context.get();
  cairo_select_font_face(cr, kFont, CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_BOLD);
  const double font = std::max(9.0, h / 30.0);
  cairo_set_font_size(cr, font);

  // The top band: title and step; h(s) and the shield's status.
  const double band = 2.7 * font;
  cairo_rectangle(cr, 0, 0, w, band);
  SetColor(cr, {0, 0, 0}, 0.6);
  cairo_fill(cr);
  const double x0 = 0.6 * font;
  cairo_move_to(cr, x0, 1.15 * font);
  const long horizon = std::max<long>(options_.max_steps, step.step);
  Text(cr, (options_.title.empty() ? "" : options_.title + "   ") + "step " +
               std::to_string(step.step) + "/" + std::to_string(horizon),
       kWhite);
  cairo_move_to(cr, x0, 2.3 * font);
  Text(cr, "h(s) " + (step.h ? Signed(*step.h) : std::string("  n/a ")) + "  ",
       step.h && *step.h < 0 ? kRed : kWhite);
  if (step.step > 0) Text(cr, step.status.empty() ? "unshielded" : step.status, StatusColor(step.status));
  if (step.intervened) Text(cr, "  INTERVENED", kOrange);
  if (step.collided) Text(cr, "  COLLISION", kRed);
  if (step.reached_goal) Text(cr, "  GOAL", kGreen);

  // The border: orange where the shield intervened, red where it found no safe action or the
  // state is dangerous.
  const bool alarm = step.collided || step.status == "no_safe_action" ||
                     step.status == "invalid_input";
  if (alarm || step.intervened) {
    const double line = std::max(3.0, h / 80.0) * (alarm ? 1.6 : 1.0);
    cairo_set_line_width(cr, line);
    cairo_rectangle(cr, line / 2, line / 2, w - line, h - line);
    SetColor(cr, alarm ? kRed : kOrange, 0.9);
    cairo_stroke(cr);
  }

  // The panel: h over the episode so far.
  if (options_.panel) {
    const double ph = std::max(3.5 * font, h / 4.0);
    const double top = h - ph;
    cairo_rectangle(cr, 0, top, w, ph);
    SetColor(cr, {0, 0, 0}, 0.55);
    cairo_fill(cr);
    const double left = 5.5 * font, right = w - 0.8 * font;
    const double plot_top = top + 0.7 * font, plot_bottom = h - 1.4 * font;
    double lo = 0.0, hi = 0.0;
    bool any = false;
    for (const Point& p : history_) {
      if (!p.h) continue;
      lo = std::min(lo, *p.h);
      hi = std::max(hi, *p.h);
      any = true;
    }
    cairo_set_font_size(cr, 0.8 * font);
    if (!any) {
      cairo_move_to(cr, left, (plot_top + plot_bottom) / 2);
      Text(cr, "h(s) not available: no barrier for this method", kGrey);
    } else {
      if (hi - lo < 1e-6) hi = lo + 1.0;
      const double pad = 0.08 * (hi - lo);
      lo -= pad;
      hi += pad;
      const double span_x = std::max<double>(1.0, static_cast<double>(horizon));
      auto X = [&](long s) { return left + (right - left) * static_cast<double>(s) / span_x; };
      auto Y = [&](double v) { return plot_bottom - (plot_bottom - plot_top) * (v - lo) / (hi - lo); };
      // Axes: h = 0 dashed, the value range at the left, the time axis below.
      const double dash[] = {4.0, 3.0};
      cairo_set_dash(cr, dash, 2, 0);
      cairo_set_line_width(cr, 1.0);
      SetColor(cr, kWhite, 0.8);
      cairo_move_to(cr, left, Y(0.0));
      cairo_line_to(cr, right, Y(0.0));
      cairo_stroke(cr);
      cairo_set_dash(cr, nullptr, 0, 0);
      // Labels: the largest and smallest h (where they stand clear of h = 0), and 0.
      cairo_move_to(cr, 0.4 * font, Y(0.0) + 0.3 * font);
      Text(cr, "h   0", kWhite);
      if (Y(0.0) - Y(hi - pad) > 1.2 * font) {
        cairo_move_to(cr, 0.4 * font, Y(hi - pad) + 0.3 * font);
        Text(cr, Signed(hi - pad), kGrey);
      }
      if (Y(lo + pad) - Y(0.0) > 1.2 * font) {
        cairo_move_to(cr, 0.4 * font, Y(lo + pad) + 0.3 * font);
        Text(cr, Signed(lo + pad), kGrey);
      }
      cairo_move_to(cr, left, h - 0.35 * font);
      Text(cr, "0", kGrey);
      const std::string end = "step " + std::to_string(horizon);
      cairo_text_extents_t extents;
      cairo_text_extents(cr, end.c_str(), &extents);
      cairo_move_to(cr, right - extents.x_advance, h - 0.35 * font);
      Text(cr, end, kGrey);
      // Interventions as ticks at the top of the plot, the h curve, collisions as dots.
      cairo_set_line_width(cr, std::max(1.5, w / 400.0));
      SetColor(cr, kOrange);
      for (const Point& p : history_) {
        if (!p.intervened) continue;
        cairo_move_to(cr, X(p.step), plot_top);
        cairo_line_to(cr, X(p.step), plot_top + 0.6 * font);
      }
      cairo_stroke(cr);
      bool pen_down = false;
      for (const Point& p : history_) {
        if (!p.h) {
          pen_down = false;
          continue;
        }
        if (pen_down) {
          cairo_line_to(cr, X(p.step), Y(*p.h));
        } else {
          cairo_move_to(cr, X(p.step), Y(*p.h));
          pen_down = true;
        }
      }
      SetColor(cr, kCyan);
      cairo_stroke(cr);
      SetColor(cr, kRed);
      for (const Point& p : history_) {
        if (!p.collided || !p.h) continue;
        cairo_new_sub_path(cr);
        cairo_arc(cr, X(p.step), Y(*p.h), std::max(2.0, font / 4), 0, 2 * M_PI);
      }
      cairo_fill(cr);
    }
  }
  cairo_surface_flush(surface.get());
  SECURE_CHECK(cairo_status(cr) == CAIRO_STATUS_SUCCESS,
               "overlay: Cairo: " << cairo_status_to_string(cairo_status(cr)));
  for (std::size_t i = 0; i < pixels_.size(); ++i) {
    const std::uint32_t v = pixels_[i];
    std::uint8_t* p = &frame.rgb[3 * i];
    p[0] = static_cast<std::uint8_t>(v >> 16);
    p[1] = static_cast<std::uint8_t>(v >> 8);
    p[2] = static_cast<std::uint8_t>(v);
  }
}

}  // namespace secure::eval
