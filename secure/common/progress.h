#pragma once
// Progress for long jobs: one line per report on stderr (never stdout, which carries --json
// results), rate-limited so that a tight loop can call Update() freely.

#include <string>

namespace secure {

class Progress {
 public:
  /// `label` prefixes every line; `total` is the number of units of work (0 if unknown).
  Progress(std::string label, long total, bool enabled = true);
  /// Reports `done` units finished and an optional status text; prints at most every 2 s.
  void Update(long done, const std::string& status = "");
  /// Prints the final line (always, if enabled).
  void Finish(const std::string& status = "");

 private:
  std::string label_;
  long total_;
  bool enabled_;
  double start_;
  double last_print_ = -1e9;
};

}  // namespace secure
