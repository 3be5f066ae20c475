#pragma once
// What a gyroscope adds to the next-pose planner (issue 21; core/planning/pose_planner.h):
//
//   rate segments  candidates of their own: a table axis that turns without a stop (the inner
//                  and outer axes of a three-axis simulator), a rate from the table's list, the
//                  other two axes at the grid's angles. Its table time is the move to its
//                  attitude, the spin-up, the steadiness window, whole revolutions of at least the
//                  dwell (the sequencer averages whole revolutions, core/sequencing/sequencer.h),
//                  and the spin-down. Only a gyroscope model learns from one.
//   moves          the turn from a static pose to the next one, which the sequencer integrates
//                  (core/sequencing/move_tracker.h) and the calibrator adds as a record
//                  (core/estimation/move_residual.h). The planner synthesises it as a gyro
//                  without errors would see it: the table's coordinated move on a cycloid profile
//                  over the move's seconds, then the settling at rest, the Earth turning
//                  throughout; weighed as the calibrator weighs a move. A move after a rate
//                  segment is none (the sequencer drops it).

#include <string>
#include <vector>

#include "core/estimation/move_record.h"
#include "core/modeling/measurement_model.h"
#include "core/planning/table_motion.h"

namespace turncal {

struct RatePlan {
  // The rates the table can hold, deg/s, either sign (0 is not a rate). Empty: the table has no
  // rate mode and the planner plans no rate segment.
  std::vector<double> rates_dps;
  // From reaching the rate to the first sample the capture may use: the steadiness detector's
  // window (the sequencer's still window, 0.5 s by default) and its look-ahead.
  double steady_s = 1.0;

  bool IsValid(std::string* error) const;
};

// The rate segments to consider: about each axis that `motion` lets turn without a stop, at each
// rate, the two held axes at every combination of `held_values` (radians; index 0 inner, 1
// middle, 2 outer; the turning axis's own list is ignored and its angle set to 0).
std::vector<TablePose> RateCandidates(const RatePlan& plan, const TableMotion& motion,
                                      const std::vector<double> held_values[3]);

// Whole revolutions at |rate|, at least `dwell_s`.
double RateCaptureSeconds(double rate_radps, double dwell_s);

// A rate segment's table time from `from`: the move to its attitude (the turning axis keeping
// from's angle) and settling, the spin-up, plan.steady_s, the capture and the spin-down; `lead_s`
// (when given) the seconds before its capture starts.
double RateSegmentSeconds(const TableMotion& motion, const RatePlan& plan, const TablePose& from,
                          const TablePose& segment, double dwell_s, double* lead_s = nullptr);

// Where the table stands after a rate segment: its attitude, the turning axis at from's angle.
TablePose AfterRateSegment(const TablePose& from, const TablePose& segment);

// The move from static `from` to static `to` as `model`'s gyroscope without errors (G_w the
// mounting, no bias) would integrate it: the coordinated move over motion.MoveSeconds, then
// motion.settle_s + `rest_s` at rest (the rest a sequencer's move also spans: before the table
// starts and until the stillness detector lets the next dwell begin), in blocks that each turn at
// most 0.1 rad (at least 8), the specific force that of gravity at rest. Times from 0. An empty
// record (no blocks) when from and to are the same pose or either is a rate segment.
MoveRecord PlannedMove(const MeasurementModel& model, const TableMotion& motion,
                       const TablePose& from, const TablePose& to, double rest_s = 0.0);

}  // namespace turncal
