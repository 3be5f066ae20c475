// The time a disturbance of the field spans (core/estimation/free_disturbance.h; issue 37): the
// values beyond the bound are joined into runs and each run widened by half its span and one
// value's spacing, so that its flanks, below the bound, leave the fit with it; a still interval
// in that time is not a sample in motion and stays.

#include "core/estimation/free_disturbance.h"

#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <vector>

#include "core/estimation/free_calibrator.h"
#include "core/modeling/free_model.h"

namespace turncal {
namespace {

// 1000 samples in motion 10 ms apart from t = 0, with a still interval (10.5-11.5 s) after them.
// The runs below span odd multiples of 10 ms, so that their windows end between two samples.
FreeData Motion() {
  FreeData d;
  for (int i = 0; i < 1000; ++i) {
    FreeInterval p;
    p.in_motion = true;
    p.t_start_s = p.t_end_s = 0.01 * i;
    d.intervals.push_back(p);
  }
  FreeInterval still;
  still.t_start_s = 10.5;
  still.t_end_s = 11.5;
  d.intervals.push_back(still);
  return d;
}

std::vector<int> Range(int from, int to) {  // [from, to]
  std::vector<int> out;
  for (int i = from; i <= to; ++i) out.push_back(i);
  return out;
}

std::vector<int> Join(std::vector<int> a, const std::vector<int>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

TEST(DisturbedSpan, JoinsRunsLessThanAQuarterSecondApartAndWidensEachByHalfItsSpan) {
  const FreeData d = Motion();
  // 4.00-4.05 s and 4.20-4.41 s, 0.15 s apart: one run of 0.41 s, widened by 0.205 + 0.01 s
  // (3.785-4.625 s); a lone value at 8.00 s, widened by one value's spacing.
  EXPECT_EQ(DisturbedSpan(d, Join(Join(Range(400, 405), Range(420, 441)), {800})),
            Join(Range(379, 462), Range(799, 801)));
}

TEST(DisturbedSpan, RunsFartherApartStayApartUnlessTheirWindowsMeet) {
  const FreeData d = Motion();
  // 1.00-1.11 s and 1.41-1.50 s, 0.30 s apart: two runs, windows 0.935-1.175 and 1.355-1.555 s.
  EXPECT_EQ(DisturbedSpan(d, Join(Range(100, 111), Range(141, 150))),
            Join(Range(94, 117), Range(136, 155)));
  // 2.00-2.41 s and 2.71-2.72 s: windows 1.785-2.625 and 2.695-2.735 s do not meet; with
  // 2.00-2.61 s and 2.91-2.92 s the first reaches 2.925 s, past the second's start, 2.895 s.
  EXPECT_EQ(DisturbedSpan(d, Join(Range(200, 241), Range(271, 272))),
            Join(Range(179, 262), Range(270, 273)));
  EXPECT_EQ(DisturbedSpan(d, Join(Range(200, 261), Range(291, 292))), Range(169, 293));
}

TEST(DisturbedSpan, LeavesTheStillIntervalsAndNothingWhenNothingIsDisturbed) {
  FreeData d = Motion();
  EXPECT_TRUE(DisturbedSpan(d, {}).empty());
  // 4.95-5.06 s: 4.885-5.125 s, less a still interval at 5.00 s.
  d.intervals[500].in_motion = false;
  EXPECT_EQ(DisturbedSpan(d, Join(Range(495, 499), Range(501, 506))),
            Join(Range(489, 499), Range(501, 512)));
}

// When the values' noise was measured correlated but the fit that whitens them fails, the fit
// that treats them as independent is kept, its sigmas too small: warned and not passed.
TEST(LeaveOutDisturbedMotion, AWhitenedFitThatFailsLeavesTheIndependentFitUnpassed) {
  std::string error;
  const auto model = MakeFreeModel("magsphere", FreeContext{}, &error);
  ASSERT_TRUE(model) << error;
  FreeCalibratorOptions options;
  options.disturbance_sigmas = 0;  // no search: the callback's fits only
  int whitened_calls = 0;
  const auto fit = [&](const FreeData&, bool whiten) {
    FreeEstimate e;
    if (whiten) {
      ++whitened_calls;
      e.estimate.error = "the solver did not converge";
      return e;
    }
    e.estimate.ok = true;
    e.motion_points = 1000;
    e.gate_passed = true;
    e.correlation.pairs = 997;
    e.correlation.lag_one = 0.52;
    e.correlation.threshold = 0.11;
    e.correlation.tau_s = 0.0154;
    return e;
  };
  const FreeEstimate out = LeaveOutDisturbedMotion(*model, Motion(), options, fit);
  EXPECT_EQ(whitened_calls, 1);
  ASSERT_TRUE(out.estimate.ok);
  EXPECT_FALSE(out.correlation.whitened);
  EXPECT_FALSE(out.gate_passed);
  ASSERT_EQ(out.gate_reasons.size(), 1u);
  EXPECT_NE(out.gate_reasons[0].find("the solver did not converge"), std::string::npos);
  EXPECT_NE(out.gate_reasons[0].find("too small"), std::string::npos);
  ASSERT_EQ(out.estimate.warnings.size(), 1u);

  // Told not to whiten, the independent fit is the answer and passes.
  options.whiten_correlated_motion = false;
  const FreeEstimate plain = LeaveOutDisturbedMotion(*model, Motion(), options, fit);
  EXPECT_EQ(whitened_calls, 1);
  EXPECT_TRUE(plain.gate_passed);
}

}  // namespace
}  // namespace turncal
