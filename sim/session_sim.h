#pragma once
// A complete turntable session as timed samples, with known truth (the sample level of
// `turncal sim`; the byte level lives in tools/). Pure computation with an explicit seed.
//
// Time line: the table rests at the home pose (0, 0, 0) for `start_s`; then for every pose it
// moves there along a smooth S-curve in each angle (`move_s`, or as long as the table's rates
// take), settles with a small decaying
// oscillation (`settle_s`), and dwells (`dwell_s`). The controller's pose event is at the start of
// the dwell. The sensor is at the table's centre of rotation: its specific force and field are
// the measurement models' stationary predictions at the current table angles (no lever-arm
// acceleration), its gyro sees the table's angular rate (Earth rate not included).
//
// Noise per sample: white noise (density x sqrt(rate / 2)), bias instability as a first-order
// Gauss-Markov process (1 sigma = the class's bias instability, correlation time the class's
// bias_tau_s), optionally a bias random walk and a warm-up transient (an offset drawn per axis
// that settles exponentially after power-on, which is time 0), quantisation for classes with a
// 16-bit ADC. The device clock runs `clock_drift_ppm` fast and starts at `clock_offset_s`.

#include <limits>
#include <optional>
#include <random>
#include <vector>

#include "core/estimation/move_record.h"
#include "core/estimation/pose_record.h"
#include "core/modeling/measurement_model.h"
#include "core/planning/table_motion.h"
#include "core/sequencing/sample.h"
#include "sim/chamber.h"
#include "sim/hand_motion.h"
#include "sim/synthetic.h"
#include "sim/thermal_truth.h"

namespace turncal {

struct SessionSimOptions {
  SensorClass sensor = IndustrialClass();
  double rate_hz = 100.0;
  double start_s = 1.0;
  double move_s = 3.0;
  double settle_s = 1.0;
  // Moves at the table's rates (core/planning/table_motion.h: each move as long as the coordinated
  // trapezoidal move takes, at least 0.1 s, the shorter way round on continuous axes, then the
  // table's settle time) instead of move_s and settle_s for every move.
  std::optional<TableMotion> table;
  double dwell_s = 5.0;
  // Bias random walk, triad unit per sqrt(s) (0: none).
  double acc_random_walk = 0.0;  // m/s^2/sqrt(s)
  double mag_random_walk = 0.0;  // Gauss/sqrt(s)
  // Warm-up: at power-on the bias is off by a draw of this 1 sigma per axis, settling as
  // exp(-t / warmup_tau_s) (0: none).
  double acc_warmup = 0.0;  // m/s^2
  double mag_warmup = 0.0;  // Gauss
  double gyr_warmup = 0.0;  // rad/s (only with a gyro model)
  double warmup_tau_s = 60.0;
  double clock_drift_ppm = 20.0;
  double clock_offset_s = 10.0;
  double settle_amplitude_rad = 2e-4;  // of the decaying oscillation after a move
  // Rate segments (a pose with TablePose::rate_axis set): the table spins up in spin_s with an
  // S-curve, holds the rate with a ripple of rate_ripple (relative, at ripple_hz) for
  // rate_settle_s and then at least dwell_s of whole revolutions (at least one) and two seconds
  // more (the sequencer's look-ahead, with room for a live run's delays), and spins down in
  // spin_s; the announcement is at the end of rate_settle_s.
  double spin_s = 1.5;
  double rate_settle_s = 0.5;
  double rate_ripple = 1e-4;
  double ripple_hz = 2.0;
  // Gyro bias random walk, rad/s/sqrt(s) (0: none; only with a gyro model).
  double gyr_random_walk = 0.0;
  // The gyro's scale grows with the table's rate: the rate it senses is w (1 + k |w|), k relative
  // per rad/s (0: linear; only with a gyro model). Not in the truth's parameters: the models are
  // linear, and the report's rate linearity shows it (core/analysis/rate_linearity.h).
  double gyr_scale_nonlinearity = 0.0;
  // The IMU's lever arm from the table's centre, in the inner frame q, m (zero: the bytes of a
  // session without one are unchanged). In motion the accelerometer (and a gyro's
  // g-sensitivity) then see the centripetal and tangential acceleration w x (w x r) + dw/dt x r
  // (dw/dt by the backward difference over one sample), turned by the nominal mounting; the
  // gyro does not (a rigid body turns alike everywhere). Still poses are unaffected.
  Eigen::Vector3d lever_arm_q_m = Eigen::Vector3d::Zero();
  // A climate chamber (issue 36; sim/chamber.h): the die's temperature follows it, every sensor
  // parameter of the models is a quadratic in that temperature (sim/thermal_truth.h; the truths
  // at the chamber's middle temperature are DrawTruth's, the coefficients drawn from a stream of
  // their own, so the session's other draws are unchanged) and the samples report it. Without
  // one, the reported temperature is a line from 25 to 25.5 degC and the parameters constant.
  std::optional<ChamberProfile> chamber;
  DieThermal die;
  // With a chamber: the poses again and again until the chamber's profile has run (a turntable
  // cycling its poses through a continuous ramp).
  bool repeat_poses_through_chamber = false;
  // A hand's continuous rotation instead of the table's poses (issue 37; sim/hand_motion.h): at
  // rest for start_s (0: no still moment at all), then the motion; the poses are ignored and no
  // pose is announced.
  std::optional<sim::HandMotion> hand;
  // The magnetometer's own sample rate, Hz: below rate_hz the device holds its last value
  // between updates (sample and hold, as MIP devices do; 0: a new value in every sample), and its
  // bandwidth, Hz: a first-order low-pass on the field before the noise (0: none; a rotating
  // field's magnitude is then attenuated by 1 / sqrt(1 + (w / (2 pi bandwidth))^2)).
  double mag_rate_hz = 0.0;
  double mag_bandwidth_hz = 0.0;
  // The magnetometer's lag behind the stream's clock, s: each sample carries the field of this
  // long before (rounded to whole samples of rate_hz; the first sample's field before the
  // session's start; 0: none).
  double mag_lag_s = 0.0;
  // With a bandwidth: the magnetometer's noise through the filter too (as a device's digital
  // filter filters its sensor's noise), scaled so that the filtered noise has the class's RMS;
  // its values are then correlated in time (exp(-2 pi bandwidth dt)). False: white noise added
  // after the filter.
  bool mag_noise_filtered = false;
  // A magnet passing by (issue 37's bad input): from magnet_at_s (session time) for magnet_s, a
  // field along magnet_direction (the sensor's frame; normalised) rising and falling as a raised
  // cosine to magnet_peak (the magnetometer's unit) at its middle; 0: none. It is not the
  // sensor's: the truth does not hold it.
  double magnet_at_s = 0.0, magnet_s = 1.0, magnet_peak = 0.0;
  Eigen::Vector3d magnet_direction = Eigen::Vector3d(1.0, 1.0, 1.0);
  std::uint64_t seed = 1;

  bool IsValid(std::string* error) const;
};

struct SessionPoseEvent {
  double t_s = 0.0;  // host time of the announcement (start of the dwell)
  int index = 0;
  TablePose pose;
  double dwell_end_s = 0.0;
  // Mean of the bias's departure from the turn-on bias over this dwell (Gauss-Markov wander,
  // random walk and warm-up: what a calibration sees as the bias at this pose, on top of the
  // turn-on bias in the truth).
  Eigen::Vector3d acc_wander_mean = Eigen::Vector3d::Zero();
  Eigen::Vector3d mag_wander_mean = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyr_wander_mean = Eigen::Vector3d::Zero();
  // A rate segment: the seconds of its whole revolutions (the announcement's dwell); the hold
  // lasts two seconds more.
  double revolutions_s = 0.0;
  // The die's true temperature averaged over the dwell (with a chamber; NaN without).
  double die_mean_c = std::numeric_limits<double>::quiet_NaN();
  // The temperature the parameters were at, averaged over the dwell: the die's through the
  // hysteresis's play (DieThermal::hysteresis_c; equal to die_mean_c without hysteresis).
  double parameter_mean_c = std::numeric_limits<double>::quiet_NaN();
};

struct SimulatedSession {
  std::vector<Sample> samples;  // t_host_ns = true time; t_device_s = device clock
  std::vector<SessionPoseEvent> events;
  Eigen::VectorXd accel_truth;
  Eigen::VectorXd mag_truth;
  Eigen::Vector3d gyro_bias_radps = Eigen::Vector3d::Zero();
  // With a gyro model: its truth (gyro_bias_radps is then its bias), and the Earth's rate and the
  // table's rate in its output.
  Eigen::VectorXd gyro_truth;
  double duration_s = 0.0;
  // With a chamber: each model's parameters as functions of the die's temperature (their values
  // at the chamber's middle temperature are accel_truth, mag_truth, gyro_truth).
  std::optional<ThermalTruth> accel_thermal, mag_thermal, gyro_thermal;

  // The wander averaged over all the dwells (the bias a calibration that treats every pose's
  // offset as independent finds: turn-on bias plus this).
  Eigen::Vector3d EffectiveAccBiasOffset() const;
  Eigen::Vector3d EffectiveMagBiasOffset() const;
  // The wander over the last pose's dwell: with the drift-aware calibrator the bias parameters
  // are the bias there (truth "bias_truth": "at_last_pose").
  Eigen::Vector3d LastPoseAccBiasOffset() const;
  Eigen::Vector3d LastPoseMagBiasOffset() const;
  // The bias's departure from the turn-on bias averaged over the samples in [t0_s, t1_s]
  // (session time): the truth of a bias estimated over that window, e.g. a calibration's
  // bias_window (when no sample falls inside -- a window one sample long, shifted by a clock's
  // microseconds -- the drift at the sample nearest the window's middle).
  Eigen::Vector3d AccDriftMean(double t0_s, double t1_s) const;
  Eigen::Vector3d MagDriftMean(double t0_s, double t1_s) const;
  Eigen::Vector3d GyrDriftMean(double t0_s, double t1_s) const;

  // Prefix sums of the bias departure per sample (size samples + 1), for the window means.
  std::vector<Eigen::Vector3d> acc_drift_sum, mag_drift_sum, gyr_drift_sum;
};

// The session for `poses` with the truths drawn from the class (DrawTruth) from the seed. With a
// gyro model (gyro12, gyro21) its truth is drawn after the others, the gyro sees the Earth's rate
// (the table's heading taken as north) and, through B_g, the specific force, and its bias wanders
// like the other triads'; without one, the gyro is the table's rate plus a turn-on bias (the
// random stream, and so the bytes, of sessions without a gyro model are unchanged).
SimulatedSession SimulateSession(const MeasurementModel& accel_model,
                                 const MeasurementModel& mag_model,
                                 const std::vector<TablePose>& poses,
                                 const SessionSimOptions& options,
                                 const MeasurementModel* gyro_model = nullptr);

// The statistics of the samples inside one pose's dwell (the ideal cut, with the simulator's
// known times; the sequencer finds windows itself): mean, sample covariance and count of the
// accelerometer, magnetometer or gyroscope triad (a rate segment: its whole revolutions), and the
// mean of the temperature the samples report.
PoseRecord DwellRecord(const SimulatedSession& session, const SessionPoseEvent& event,
                       SensorKind sensor);

// The move from pose event `from` to pose event `to` as the gyro saw it (the ideal cut, with the
// simulator's known times): the raw gyro integrated over blocks of `block_s` (whole samples,
// at least one) from the end of `from`'s dwell to the start of `to`'s, the raw accelerometer's
// mean per block, times in session seconds (core/estimation/move_record.h).
MoveRecord MoveBetween(const SimulatedSession& session, const SessionPoseEvent& from,
                       const SessionPoseEvent& to, double rate_hz, double block_s = 0.01);

// The default plan: the 26 cube directions, then 10 rotations about intermediate axes (down along
// directions between the cube's, psi varied), 36 poses in all.
std::vector<TablePose> DefaultSessionPoses();

// The default rate segments for a gyroscope (issue 21): +-rate_dps about the inner axis, the middle
// axis (inner at 0), and the outer axis (inner and middle at 0, then the middle at 90 deg, which
// turns the outer axis onto q's x), so that q's three axes each see both signs; with
// `two_rates` the same again at a third of the rate, which exposes a rate-dependent scale.
std::vector<TablePose> DefaultRateSegments(double rate_dps = 100.0, bool two_rates = true);

}  // namespace turncal
