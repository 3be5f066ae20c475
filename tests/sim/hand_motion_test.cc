// Issue 37: the hand's path (sim/hand_motion.h): its rates are the derivative of its angles, it
// turns at the RMS rate asked for, stops in its pauses without a step in the rate, and holds still
// at its ends; and a session with it samples the magnetometer at its own rate, holding between.

#include "sim/hand_motion.h"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>

#include "core/frames/rotations.h"
#include "core/modeling/measurement_model.h"
#include "sim/session_sim.h"

namespace turncal::sim {
namespace {

Eigen::Vector3d BodyRate(const HandPath& p, double t) {
  const double h = 1e-5;
  Eigen::Vector3d a0, a1, r;
  p.At(t - h, &a0, &r);
  p.At(t + h, &a1, &r);
  const Mat3<double> C0 = C_p_q(a0[0], a0[1], a0[2]), C1 = C_p_q(a1[0], a1[1], a1[2]);
  const Eigen::AngleAxisd d(Eigen::Matrix3d(C0.transpose() * C1));
  return d.axis() * d.angle() / (2 * h);
}

TEST(HandMotion, RatesAreTheAnglesDerivativeAndTheRmsRateIsAsAsked) {
  for (auto path :
       {HandMotion::Path::kTumble, HandMotion::Path::kFigureEight, HandMotion::Path::kPlanar}) {
    HandMotion m;
    m.path = path;
    m.duration_s = 60;
    m.rate_dps = 120;
    const HandPath p(m, 3);
    double sum = 0;
    int n = 0;
    for (double t = 1.0; t < 59.0; t += 0.0137) {
      Eigen::Vector3d a, r, a2, r2;
      p.At(t, &a, &r);
      p.At(t + 1e-6, &a2, &r2);
      EXPECT_LT(((a2 - a) / 1e-6 - r).norm(), 1e-4 * (1 + r.norm())) << HandPathName(path) << t;
      sum += BodyRate(p, t).squaredNorm();
      ++n;
    }
    const double rms_dps = std::sqrt(sum / n) * 180 / M_PI;
    EXPECT_NEAR(rms_dps, 120.0, 120.0 * 0.25) << HandPathName(path);
  }
}

TEST(HandMotion, PausesStopSmoothlyAndTheEndsAreStill) {
  HandMotion m;
  m.duration_s = 20;
  m.pause_every_s = 5;
  m.pause_s = 1.5;
  const HandPath p(m, 1);
  Eigen::Vector3d a, r;
  p.At(5.75, &a, &r);  // the middle of the first pause
  EXPECT_LT(r.norm(), 1e-12);
  p.At(0.0, &a, &r);
  EXPECT_LT(r.norm(), 1e-12);
  p.At(20.0, &a, &r);
  EXPECT_LT(r.norm(), 1e-12);
  // No step in the rate anywhere: between two instants 1 ms apart the rate moves by little.
  double worst = 0;
  Eigen::Vector3d prev;
  p.At(0.0, &a, &prev);
  for (double t = 0.001; t <= 20.0; t += 0.001) {
    p.At(t, &a, &r);
    worst = std::max(worst, (r - prev).norm());
    prev = r;
  }
  EXPECT_LT(worst, 0.05);  // rad/s per ms: an acceleration below 50 rad/s^2
  // The motion time lost in pauses: the angles after a pause continue where they stopped.
  Eigen::Vector3d before, after;
  p.At(5.0 + 0.3, &before, &r);
  p.At(5.0 + 1.2, &after, &r);
  EXPECT_LT((after - before).norm(), 0.05);
}

// A 1-kHz session of a 2-s hand rotation after start_s at rest, and the models it simulates.
struct HandSession {
  SessionSimOptions options;
  std::unique_ptr<MeasurementModel> accel, mag;
  explicit HandSession(double start_s) {
    options.rate_hz = 1000;
    options.start_s = start_s;
    HandMotion m;
    m.duration_s = 2;
    options.hand = m;
    std::string error;
    accel = MakeModel("accel13", ModelContext{}, &error);
    mag = MakeModel("mag13", ModelContext{}, &error);
  }
  SimulatedSession Run() const { return SimulateSession(*accel, *mag, {}, options); }
};

TEST(HandMotion, TheMagnetometerHoldsBetweenItsOwnSamples) {
  HandSession h(0.0);
  SessionSimOptions& o = h.options;
  o.mag_rate_hz = 100;
  std::string error;
  ASSERT_TRUE(o.IsValid(&error)) << error;
  const SimulatedSession s = h.Run();
  ASSERT_EQ(s.samples.size(), 2000u);
  EXPECT_TRUE(s.events.empty());
  int fresh = 0;
  for (std::size_t k = 1; k < s.samples.size(); ++k) {
    fresh += *s.samples[k].mag != *s.samples[k - 1].mag;
    EXPECT_NE(*s.samples[k].acc_mps2, *s.samples[k - 1].acc_mps2);
  }
  EXPECT_EQ(fresh, 199);  // a new value every 10th sample
  o.hand->pause_s = 0.1;
  o.hand->pause_every_s = 1;
  EXPECT_FALSE(o.IsValid(&error));  // a pause shorter than its two ramps
  EXPECT_NE(error.find("ramps"), std::string::npos) << error;
}

// A magnetometer whose filter filters its noise too (--mag-noise-filtered): the filter has run
// since power-on, so its first value's noise is at the output's steady level, not the raw draw's
// (5.6 times larger at 10 Hz of 1 kHz: its first 50 ms read as a magnet passing by in a quarter
// of the free rows' runs, and their chi^2 came out 1 % large).
TEST(HandMotion, AFilteredNoiseStartsInItsSteadyState) {
  HandSession h(1.0);  // still for the first second
  SessionSimOptions& o = h.options;
  o.mag_bandwidth_hz = 10;
  o.mag_noise_filtered = true;
  std::string error;
  ASSERT_TRUE(o.IsValid(&error)) << error;
  // Per seed, the x axis's first value and a later one (0.4 s) less the mean of 0.5-1 s (the
  // field the same, still): their variances over the seeds should be alike.
  double first = 0, later = 0;
  const int seeds = 60;
  for (int seed = 1; seed <= seeds; ++seed) {
    o.seed = static_cast<std::uint64_t>(seed);
    const SimulatedSession s = h.Run();
    ASSERT_GE(s.samples.size(), 1000u);
    double mean = 0;
    for (std::size_t k = 500; k < 1000; ++k) mean += s.samples[k].mag->x() / 500;
    first += std::pow(s.samples[0].mag->x() - mean, 2) / seeds;
    later += std::pow(s.samples[400].mag->x() - mean, 2) / seeds;
  }
  // The ratio of two variances over 60 seeds has the sigma 0.26: 4 sigma (a raw draw's: 31).
  EXPECT_NEAR(first / later, 1.0, 1.0) << first << " " << later;
}

}  // namespace
}  // namespace turncal::sim
