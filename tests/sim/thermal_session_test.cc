// The session simulator in a climate chamber (sim/session_sim.h `chamber`; issue 36): the die's
// temperature in every sample, the parameters following it, and a calibration over temperature
// from the dwells of a session whose poses cycle through a ramp, with the class's drift in time.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "core/estimation/sensor_class.h"
#include "core/estimation/thermal_calibrator.h"
#include "core/planning/pose_designs.h"
#include "tests/support/simulated_session.h"

namespace turncal {
namespace {

SessionSimOptions ChamberOptions(const std::string& profile) {
  SessionSimOptions o;
  o.rate_hz = 50;
  o.dwell_s = 4;
  o.move_s = 2;
  o.settle_s = 0.5;
  std::string error;
  ChamberProfile chamber;
  EXPECT_TRUE(ChamberProfile::Parse(profile, &chamber, &error)) << error;
  o.chamber = chamber;
  o.die.tau_s = 120;
  o.die.self_heating_c = 2;
  o.die.self_heating_tau_s = 300;
  o.repeat_poses_through_chamber = true;
  return o;
}

// The samples report the die, which lags the ramp; the poses are repeated until the chamber's
// profile has run; without a chamber nothing of this appears and the draws are the same.
TEST(ThermalSession, TheSamplesReportTheDieAndThePosesCycleThroughTheRamp) {
  const SessionSimOptions o = ChamberOptions("0; ramp 40 4 0");  // 600 s up at 4 degC/min
  const SimulatedRun run = SimulateAccelMagSession(CubePoses26(), o);
  ASSERT_TRUE(run.sim.accel_thermal && run.sim.mag_thermal);
  EXPECT_GE(run.sim.duration_s, o.chamber->duration_s());
  EXPECT_GT(run.sim.events.size(), 26u);
  // At 500 s the air is at 33.3 degC; the die lags by about rate x tau = 8 degC and sits ~1.6
  // degC above it from self-heating.
  const Sample& s = run.sim.samples[500 * 50];
  ASSERT_TRUE(s.temp_c);
  EXPECT_NEAR(*s.temp_c, 40.0 * 500 / 600 - 4.0 / 60 * 120 + 2 * (1 - std::exp(-500.0 / 300)), 0.5);
  for (const auto& e : run.sim.events) ASSERT_TRUE(std::isfinite(e.die_mean_c));
  // The truths at the chamber's middle (20 degC) are the constant session's.
  SessionSimOptions flat = o;
  flat.chamber.reset();
  const SimulatedRun plain = SimulateAccelMagSession(CubePoses26(), flat);
  EXPECT_EQ(plain.sim.accel_truth, run.sim.accel_truth);
  EXPECT_EQ(run.sim.accel_thermal->ThetaAt(20.0), run.sim.accel_truth);
  EXPECT_FALSE(plain.sim.accel_thermal);
  EXPECT_TRUE(std::isnan(plain.sim.events[0].die_mean_c));
}

// A consumer accelerometer whose parameters follow a -10 -> 50 -> -10 degC ramp (heating then
// cooling: the temperature returns, the time does not), its poses cycling through it, with the
// class's bias wander; calibrated over temperature from the ideal dwell cuts with the class's
// drift as a process in time. At two temperatures the ramp passed, each sensor parameter is within
// 4 sigma of the truth (the biases' truth: the thermal curve plus the wander over the last dwell,
// which the drift-aware estimate refers to).
TEST(ThermalSession, ACalibrationOverARampRecoversTheParametersAtTemperaturesBetween) {
  SessionSimOptions o = ChamberOptions("-10; ramp 50 3 0; ramp -10 3 0");  // 2400 s
  o.sensor = ConsumerClass();
  const SimulatedRun run = SimulateAccelMagSession(CubePoses26(), o);
  std::vector<PoseRecord> records;
  for (const auto& e : run.sim.events) {
    records.push_back(DwellRecord(run.sim, e, SensorKind::kAccelerometer));
  }
  ASSERT_GT(records.size(), 200u);
  const CalibratorOptions options = DriftOptionsForClass(*run.accel, o.sensor);
  ThermalOptions thermal;
  thermal.orders = run.sim.accel_thermal->basis.orders;  // the truth's shape
  const ThermalEstimate est = CalibrateOverTemperature(options, records, thermal);
  ASSERT_TRUE(est.ok) << est.error;
  if (std::getenv("TURNCAL_THERMAL_DEBUG")) std::printf("%s\n", est.BriefReport().c_str());
  const Eigen::Vector3d wander = run.sim.events.back().acc_wander_mean;
  const int bx = run.accel->index_of("bx");
  for (double t : {5.0, 30.0}) {
    Eigen::VectorXd truth = run.sim.accel_thermal->ThetaAt(t);
    truth.segment<3>(bx) += wander;
    const Eigen::VectorXd err = est.ThetaAt(t) - truth, sigma = est.SigmaAt(t);
    for (int p = 0; p < err.size(); ++p) {
      if (run.accel->parameters()[static_cast<std::size_t>(p)].kind != ParameterKind::kSensor) {
        continue;
      }
      EXPECT_LT(std::abs(err[p]), 4.0 * sigma[p])
          << run.accel->parameters()[static_cast<std::size_t>(p)].name << " at " << t << "\n"
          << est.BriefReport();
    }
  }
}

}  // namespace
}  // namespace turncal
