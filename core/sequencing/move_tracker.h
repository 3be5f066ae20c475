#pragma once
// The moves between static poses as the gyro saw them (issue 21, the third source; DESIGN.md
// "Pose sources"): the sequencer hands every sample, in order, to a MoveTracker, which
// integrates the raw gyro (core/estimation/move_integrator.h) from the last sample of a captured
// static pose's dwell to the first sample of the next static pose's dwell (the windows of moves
// and records do not overlap: their white noise is their own); the next pose's record carries
// the move that led to it (PoseRecord::move_in).
//
// Both ends are samples the sequencer vouched for: the table rested at the announced pose there
// (still, and the dwell's mean fitted). A move is dropped, with its reason counted, when
//   - a sample in it lacks the gyro or was flagged (a saturated gyro loses angle);
//   - more than max_gap_samples in a row were lost or left out (the trapezoid bridges a gap
//     of a few samples: the error is of the order of the rate's curvature times the gap cubed);
//   - it lasts longer than max_s (its blocks' memory is bounded: max_s / block_s blocks);
//   - the stream was interrupted, the next pose was rejected or skipped, a rate segment came
//     between (a rate segment's end attitude is not known), or the input ended.
// Pure computation.

#include <cstdint>
#include <optional>
#include <string>

#include "core/estimation/move_integrator.h"
#include "core/sequencing/stillness.h"

namespace turncal {

struct MoveTrackerOptions {
  bool enabled = true;      // [sequencer] moves
  double block_s = 0.01;    // [sequencer] move_block_s: the blocks the gyro is integrated in
  double max_s = 120.0;     // [sequencer] move_max_s: a longer move is dropped
  int max_gap_samples = 2;  // lost or left out in a row, bridged
  bool IsValid(std::string* error) const;
};

class MoveTracker {
 public:
  explicit MoveTracker(MoveTrackerOptions options) : options_(options) {}

  // The device's nominal sample period (the integral's time step; see MoveIntegrator).
  void SetPeriod(double period_s) { period_s_ = period_s; }
  // A static pose was captured; `last` is its dwell's last sample.
  void Start(const TablePose& from, const StillSample& last);
  // The next sample in the stream (ignored unless a move is being tracked).
  void Add(const StillSample& s);
  // The next static pose's dwell begins at the last sample added: the move ends there.
  void End(const TablePose& to);
  // The move that ended, for the record of the pose it led to (once).
  std::optional<MoveRecord> TakeEnded();
  // Drops what is tracked or ended ("" when nothing was: not counted).
  void Abort(const std::string& why);
  // Free mode: an ended move goes on integrating in the background until it is taken, so that a
  // dwell which then fails (a still segment skipped) becomes part of the move instead of ending
  // it. Resume() takes the move up again; false when there is none to resume (then Abort).
  void SetResumable(bool resumable) { resumable_ = resumable; }
  bool Resume();

  bool tracking() const { return integrator_.has_value() && !ended_; }
  std::int64_t moves() const { return moves_; }      // ended and taken
  std::int64_t dropped() const { return dropped_; }  // with a reason
  const std::string& last_drop() const { return last_drop_; }

 private:
  MoveTrackerOptions options_;
  double period_s_ = 0.0;
  std::optional<MoveIntegrator> integrator_;
  TablePose from_;
  bool ended_ = false;
  std::optional<MoveRecord> done_;
  bool resumable_ = false;
  std::optional<MoveIntegrator> shadow_;  // the ended move, integrating on (resumable_)
  std::int64_t moves_ = 0, dropped_ = 0;
  std::string last_drop_;
};

}  // namespace turncal
