#pragma once
// ProgressLine: a live progress line for long commands (demo, experiments, training) that stays
// quiet when the output is not a terminal.
//
//   ProgressLine progress(&std::cerr, ProgressLine::IsTerminal(stderr));
//   progress.Start(total, "experiment");
//   progress.Milestone("[seed 0] AIRL: ...");   // a whole line, above the live line
//   progress.Advance();                         // from any thread
//   progress.Finish();                          // clears the live line
//
// Live (a terminal, or --progress always): "label: 3/10 (30%), 0:12 elapsed, ~0:28 left",
// redrawn in place with '\r' at most every `min_redraw_seconds` (0.1 s by default) and cleared by
// Finish(); milestone lines are printed above it. Not live (a pipe, a file, a CI log, or
// --progress never): only the milestone lines, each written whole and flushed, exactly as they
// are given. All methods are thread-safe: seeds running in parallel share one line, and its
// counts are their sum. The estimated time left is the average time per unit completed since
// Start() times the units left.
//
// Trainers that print their own status lines on stderr (the AIRL "[airl] it ..." lines) route
// them through PrintStatusLine(), so they land above a live line that is installed
// (ProgressLine::Install) instead of breaking it.
#include <chrono>
#include <cstdio>
#include <mutex>
#include <ostream>
#include <string>

#include "secure/common/enum_strings.h"

namespace secure {

/// --progress: auto (live when stderr is a terminal), always, never.
enum class ProgressMode { kAuto, kAlways, kNever };
inline constexpr EnumTable<ProgressMode, 3> kProgressModeNames{{{ProgressMode::kAuto, "auto"},
                                                                {ProgressMode::kAlways, "always"},
                                                                {ProgressMode::kNever, "never"}}};

class ProgressLine {
 public:
  using Clock = std::chrono::steady_clock;

  /// `out` may be null (nothing is printed). `live`: draw the live line.
  ProgressLine(std::ostream* out, bool live, double min_redraw_seconds = 0.1);
  /// Clears the live line and uninstalls itself.
  ~ProgressLine();
  ProgressLine(const ProgressLine&) = delete;
  ProgressLine& operator=(const ProgressLine&) = delete;

  /// Whether `stream` is a terminal (isatty).
  static bool IsTerminal(std::FILE* stream);
  /// live for a mode: kAuto -> IsTerminal(stream).
  static bool Live(ProgressMode mode, std::FILE* stream = stderr);

  bool live() const { return live_ && out_ != nullptr; }

  /// Starts (or restarts) counting: `total` units, `done` of them already done (they count
  /// towards done/total but not towards the time per unit). Draws the line at once.
  void Start(long total, const std::string& label, long done = 0);
  /// Adds `n` units to the total (work found to be needed after Start).
  void AddTotal(long n);
  /// `n` more units done; redraws (at most every min_redraw_seconds).
  void Advance(long n = 1);
  /// Prints `line` (without its newline) as a line of its own; live, above the live line.
  void Milestone(const std::string& line);
  /// Clears the live line (when drawn); later Advance calls do not draw until the next Start.
  void Finish();

  long done() const;
  long total() const;

  /// The live line's text: "label: done/total (p%), M:SS elapsed, ~M:SS left" (the estimate
  /// "--:--" until a unit is done; "H:MM:SS" above an hour).
  static std::string Format(const std::string& label, long done, long total, double elapsed,
                            long done_since_start);
  /// "M:SS", or "H:MM:SS".
  static std::string Duration(double seconds);

  /// Makes this line the one PrintStatusLine() writes above (while it lives or until
  /// Uninstall()); one at a time, the last installed wins.
  void Install();
  void Uninstall();

 private:
  void DrawLocked(bool force);
  void ClearLocked();

  std::ostream* out_;
  bool live_;
  double min_redraw_seconds_;
  mutable std::mutex mutex_;
  std::string label_;
  long total_ = 0, done_ = 0, done_at_start_ = 0;
  bool started_ = false;
  Clock::time_point start_, last_draw_;
  bool drawn_ = false;
  std::size_t drawn_width_ = 0;
};

/// Prints a status line (no trailing newline needed) of a trainer's verbose output: above the
/// installed ProgressLine if any, else on stderr.
void PrintStatusLine(const std::string& line);
/// PrintStatusLine of a printf-formatted line (a trailing newline in `format` is dropped).
void PrintStatusLineF(const char* format, ...) __attribute__((format(printf, 1, 2)));

}  // namespace secure
