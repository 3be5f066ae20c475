#include <algorithm>
#include <cmath>
#include <deque>
#include <optional>
#include <random>

#include "sim/session_sim.h"
#include "sim/table_kinematics.h"

// SimulateSession (sim/session_sim.h): the table's schedule and the samples along it.
namespace turncal {

namespace {

using sim::SCurve;
double SCurveRate(double s) { return 0.5 * M_PI * std::sin(M_PI * s); }
// Smooth step 0 -> 1 with zero rate and zero acceleration at both ends: s - sin(2 pi s) / (2 pi).
double Cycloid(double s) { return s - std::sin(2 * M_PI * s) / (2 * M_PI); }
double CycloidRate(double s) { return 1.0 - std::cos(2 * M_PI * s); }

struct Angles {
  Eigen::Vector3d value = Eigen::Vector3d::Zero();  // phi, gamma, psi
  Eigen::Vector3d rate = Eigen::Vector3d::Zero();
};

Eigen::Vector3d Vec(const TablePose& p) { return {p.phi_rad, p.gamma_rad, p.psi_rad}; }

Eigen::Vector3d BodyRate(const Angles& a) { return sim::TableBodyRate(a.value, a.rate); }

double Quantise(double v, double q) { return q > 0 ? q * std::round(v / q) : v; }

// The index in (phi, gamma, psi) of a rate segment's rotating axis; -1 for a static pose.
int SpinIndex(TableAxis axis) {
  switch (axis) {
    case TableAxis::kNone:
      return -1;
    case TableAxis::kInner:
      return 0;
    case TableAxis::kMiddle:
      return 1;
    case TableAxis::kOuter:
      return 2;
  }
  return -1;
}

// A piece of the schedule: resting at `to`, moving from `from` to `to`, or (spin >= 0) turning one
// axis at a rate: an S-curve spin-up over up_s, the rate with a sinusoidal ripple for hold_s, and
// an S-curve spin-down over up_s.
struct Segment {
  double t0, t1;
  Eigen::Vector3d from, to;
  bool moving;
  int spin = -1;
  bool hand = false;  // the hand's motion (HandPath), from t0
  double rate = 0.0, up_s = 0.0, hold_s = 0.0, ripple = 0.0, ripple_hz = 0.0;
  double ripple_phase = 0.0;  // rad, drawn per segment: a table's ripple is not locked to a window

  // The rotating axis's angle and rate `since` seconds after t0.
  std::pair<double, double> AngleRate(double since) const {
    const double a0 = from[spin];
    const auto ramp = sim::SCurveIntegral;
    if (since < up_s) {
      const double u = since / up_s;
      return {a0 + rate * up_s * ramp(u), rate * SCurve(u)};
    }
    const double up_angle = a0 + rate * up_s * ramp(1.0);
    const double w = 2 * M_PI * ripple_hz;
    const double tau = std::min(since - up_s, hold_s);
    const double p = ripple_phase;
    const double hold_angle =
        up_angle + rate * (tau + ripple * (std::cos(p) - std::cos(w * tau + p)) / w);
    if (since - up_s < hold_s) return {hold_angle, rate * (1 + ripple * std::sin(w * tau + p))};
    const double u = std::min((since - up_s - hold_s) / up_s, 1.0);
    return {hold_angle + rate * up_s * (u - ramp(u)), rate * (1 - SCurve(u))};
  }
};

// The session's random stream: one generator and one normal distribution, which keeps the second
// value of each pair it draws. Every draw goes through it in the order the draws were always
// made, so that a seed gives the bytes it gave.
struct RandomStream {
  explicit RandomStream(std::uint64_t seed) : rng(seed) {}
  double Normal() { return normal(rng); }
  std::mt19937_64 rng;
  std::normal_distribution<double> normal{0.0, 1.0};
};

// The slowly varying part of each triad's error: a Gauss-Markov wander (phi, drive per sample),
// a random walk and a warm-up offset that settles after power-on. The gyro's only with a gyro
// model.
struct Drift {
  double phi = 0, drive = 0;
  double walk_acc_step = 0, walk_mag_step = 0, walk_gyr_step = 0;
  Eigen::Vector3d wander_acc, wander_mag, wander_gyr = Eigen::Vector3d::Zero();
  Eigen::Vector3d walk_acc = Eigen::Vector3d::Zero(), walk_mag = Eigen::Vector3d::Zero(),
                  walk_gyr = Eigen::Vector3d::Zero();
  Eigen::Vector3d warm_acc = Eigen::Vector3d::Zero(), warm_mag = Eigen::Vector3d::Zero(),
                  warm_gyr = Eigen::Vector3d::Zero();
};

// SimulateSession's steps: the truth drawn, the table's schedule planned, the drift started, then
// sample by sample the table's angles, the drift's step and the measurements with their noise,
// and at the end each dwell's mean drift.
class SessionSimulator {
 public:
  SessionSimulator(const MeasurementModel& accel_model, const MeasurementModel& mag_model,
                   const SessionSimOptions& o, const MeasurementModel* gyro_model)
      : accel_model_(accel_model),
        mag_model_(mag_model),
        gyro_model_(gyro_model),
        o_(o),
        c_(o.sensor),
        random_(o.seed),
        settle_s_(o.table ? o.table->settle_s : o.settle_s),
        dt_(1.0 / o.rate_hz),
        earth_ned_(EarthRateNed(accel_model.context().reference)),
        f_ned_(SpecificForceNed(accel_model.context().reference)) {}

  SimulatedSession Simulate(const std::vector<TablePose>& poses) {
    DrawTruths();
    if (o_.hand) {
      PlanHand();
    } else {
      PlanSchedule(poses);
    }
    if (o_.chamber && o_.repeat_poses_through_chamber && out_.duration_s > 0 &&
        out_.duration_s < o_.chamber->duration_s()) {
      // The poses again and again until the chamber's profile has run.
      const auto passes =
          static_cast<std::size_t>(std::ceil(o_.chamber->duration_s() / out_.duration_s));
      std::vector<TablePose> repeated;
      for (std::size_t i = 0; i < passes; ++i)
        repeated.insert(repeated.end(), poses.begin(), poses.end());
      segments_.clear();
      out_.events.clear();
      PlanSchedule(repeated);
    }
    StartDrift();
    const auto n = static_cast<std::size_t>(std::floor(out_.duration_s * o_.rate_hz));
    out_.samples.reserve(n);
    out_.acc_drift_sum.assign(1, Eigen::Vector3d::Zero());
    out_.mag_drift_sum.assign(1, Eigen::Vector3d::Zero());
    if (gyro_model_) out_.gyr_drift_sum.assign(1, Eigen::Vector3d::Zero());
    out_.acc_drift_sum.reserve(n + 1);
    out_.mag_drift_sum.reserve(n + 1);
    std::size_t seg = 0;
    for (std::size_t k = 0; k < n; ++k) {
      const double tk = static_cast<double>(k) * dt_;
      while (seg + 1 < segments_.size() && tk >= segments_[seg].t1) ++seg;
      out_.samples.push_back(SimulateSample(k, tk, TableAt(seg, tk)));
    }
    SetDwellWanderMeans();
    return std::move(out_);
  }

 private:
  void DrawTruths() {
    out_.accel_truth = DrawTruth(accel_model_, c_, &random_.rng);
    out_.mag_truth = DrawTruth(mag_model_, c_, &random_.rng);
    for (int i = 0; i < 3; ++i) out_.gyro_bias_radps[i] = c_.gyr_turn_on_bias * random_.Normal();
    if (gyro_model_) {
      out_.gyro_truth = DrawTruth(*gyro_model_, c_, &random_.rng);
      out_.gyro_bias_radps = out_.gyro_truth.segment<3>(gyro_model_->index_of("bx"));
    }
    if (o_.chamber) {
      // From a stream of their own: the session's draws stay as they were.
      std::mt19937_64 thermal_rng(o_.seed ^ 0x7e3a1c5ull);
      const double t0 = o_.chamber->middle_c();
      out_.accel_thermal =
          DrawThermalTruthAbout(accel_model_, c_, out_.accel_truth, t0, &thermal_rng);
      out_.mag_thermal = DrawThermalTruthAbout(mag_model_, c_, out_.mag_truth, t0, &thermal_rng);
      if (gyro_model_) {
        out_.gyro_thermal =
            DrawThermalTruthAbout(*gyro_model_, c_, out_.gyro_truth, t0, &thermal_rng);
      }
      die_.emplace(*o_.chamber, o_.die);
      die_sum_.assign(1, 0.0);
      param_sum_.assign(1, 0.0);
    }
  }

  // A hand's motion: at rest where it starts for start_s, then the motion (no pose events).
  void PlanHand() {
    hand_.emplace(*o_.hand, o_.seed);
    Eigen::Vector3d at, rate;
    hand_->At(0.0, &at, &rate);
    double t = 0;
    if (o_.start_s > 0) segments_.push_back({t, t + o_.start_s, at, at, false});
    t += o_.start_s;
    Segment s{t, t + o_.hand->duration_s, at, at, false};
    s.hand = true;
    segments_.push_back(s);
    out_.duration_s = t + o_.hand->duration_s;
  }

  // The table's time line: at rest at home for start_s, then per pose a move, the settling and
  // the dwell (or, for a rate segment, the spin); the pose events and the session's length.
  void PlanSchedule(const std::vector<TablePose>& poses) {
    std::mt19937_64 ripple_rng(o_.seed ^ 0x51dd1e5ull);
    double t = 0;
    Eigen::Vector3d at = Eigen::Vector3d::Zero();
    segments_.push_back({t, t + o_.start_s, at, at, false});
    t += o_.start_s;
    for (std::size_t i = 0; i < poses.size(); ++i) {
      TablePose goal = poses[i];
      const int spin = SpinIndex(goal.rate_axis);
      if (spin >= 0) {
        // The rotating axis stays where it is while the others move to their angles.
        (spin == 0 ? goal.phi_rad : spin == 1 ? goal.gamma_rad : goal.psi_rad) = at[spin];
      }
      Eigen::Vector3d target = Vec(goal);
      double move_s = o_.move_s;
      if (o_.table) {
        const TablePose from{at[0], at[1], at[2]};
        target = at + o_.table->Travel(from, goal);
        move_s = std::max(o_.table->MoveSeconds(from, goal), 0.1);
      }
      segments_.push_back({t, t + move_s, at, target, true});
      t += move_s;
      SessionPoseEvent e;
      e.index = static_cast<int>(i);
      e.pose = poses[i];
      if (spin < 0) {
        segments_.push_back({t, t + settle_s_ + o_.dwell_s, target, target, false});
        e.t_s = t + settle_s_;
        e.dwell_end_s = t + settle_s_ + o_.dwell_s;
        out_.events.push_back(e);
        t += settle_s_ + o_.dwell_s;
        at = target;
        continue;
      }
      const Segment& sp = AddSpin(&t, target, spin, goal.rate_radps, &e, &ripple_rng);
      out_.events.push_back(e);
      t = sp.t1;
      at = sp.to;
    }
    out_.duration_s = t;
  }

  // A rate segment from `target` at *t: the settling, then the spin (whole revolutions of at
  // least the dwell); *t moves past the settling, `e` gets its times.
  const Segment& AddSpin(double* t, const Eigen::Vector3d& target, int spin, double rate,
                         SessionPoseEvent* e, std::mt19937_64* ripple_rng) {
    segments_.push_back({*t, *t + settle_s_, target, target, false});
    *t += settle_s_;
    const double turn_s = 2 * M_PI / std::abs(rate);
    e->revolutions_s = std::max(1.0, std::ceil(o_.dwell_s / turn_s)) * turn_s;
    Segment sp{*t, 0.0, target, target, false};
    sp.spin = spin;
    sp.rate = rate;
    sp.up_s = o_.spin_s;
    sp.hold_s = o_.rate_settle_s + e->revolutions_s + 2.0;
    sp.ripple = o_.rate_ripple;
    sp.ripple_hz = o_.ripple_hz;
    // The ripple's phase at the hold's start, from its own stream (the session's stays as it was):
    // locked to the hold it made the same error of up to 4e-6 of the rate in every session's
    // segments (2 pi f T apart), which the Monte Carlo saw as a scale bias of 0.2 sigma.
    sp.ripple_phase = std::uniform_real_distribution<double>(0.0, 2 * M_PI)(*ripple_rng);
    sp.t1 = *t + 2 * sp.up_s + sp.hold_s;
    sp.to[spin] = sp.AngleRate(sp.t1 - sp.t0).first;
    segments_.push_back(sp);
    e->t_s = *t + sp.up_s + o_.rate_settle_s;
    e->dwell_end_s = e->t_s + e->revolutions_s;
    return segments_.back();
  }

  // The drift's state at power-on, and its per-sample constants.
  void StartDrift() {
    const double phi = std::exp(-dt_ / c_.bias_tau_s);
    drift_.phi = phi;
    drift_.drive = std::sqrt(1.0 - phi * phi);
    for (int i = 0; i < 3; ++i) {
      drift_.wander_acc[i] = c_.acc_bias_instability * random_.Normal();
      drift_.wander_mag[i] = c_.mag_bias_instability * random_.Normal();
    }
    drift_.walk_gyr_step = o_.gyr_random_walk * std::sqrt(dt_);
    if (gyro_model_) {
      for (int i = 0; i < 3; ++i) drift_.wander_gyr[i] = c_.gyr_bias_instability * random_.Normal();
    }
    // Random walk and warm-up (drawn only when asked for, so that sessions without them keep the
    // random stream, and the bytes, they had).
    drift_.walk_acc_step = o_.acc_random_walk * std::sqrt(dt_);
    drift_.walk_mag_step = o_.mag_random_walk * std::sqrt(dt_);
    for (int i = 0; i < 3; ++i) {
      if (o_.acc_warmup > 0) drift_.warm_acc[i] = o_.acc_warmup * random_.Normal();
      if (o_.mag_warmup > 0) drift_.warm_mag[i] = o_.mag_warmup * random_.Normal();
    }
    if (gyro_model_ && o_.gyr_warmup > 0) {
      for (int i = 0; i < 3; ++i) drift_.warm_gyr[i] = o_.gyr_warmup * random_.Normal();
    }
  }

  // The table's angles and their rates at tk, in segment `seg`.
  Angles TableAt(std::size_t seg, double tk) const {
    const Segment& s = segments_[seg];
    Angles a;
    if (s.hand) {
      hand_->At(tk - s.t0, &a.value, &a.rate);
    } else if (s.spin >= 0) {
      a.value = s.from;
      const auto [angle, rate] = s.AngleRate(tk - s.t0);
      a.value[s.spin] = angle;
      a.rate[s.spin] = rate;
    } else if (s.moving) {
      const double u = (tk - s.t0) / (s.t1 - s.t0);
      if (gyro_model_ == nullptr) {
        a.value = s.from + (s.to - s.from) * SCurve(u);
        a.rate = (s.to - s.from) * SCurveRate(u) / (s.t1 - s.t0);
      } else {
        // With a gyro model the acceleration is continuous too (a real table's servo limits the
        // jerk): SCurve's rate starts with a step in acceleration, which a point-sampled gyro's
        // trapezoid integral misses by dt^2 / 12 on average per step, the same sign at both
        // ends of a move (1.1e-5 rad at 100 Hz). Sessions without a gyro model keep their bytes.
        a.value = s.from + (s.to - s.from) * Cycloid(u);
        a.rate = (s.to - s.from) * CycloidRate(u) / (s.t1 - s.t0);
      }
    } else {
      a.value = s.to;
      // A decaying oscillation after a move (the table's servo settling).
      const double since = tk - s.t0;
      if (seg > 0 && since < settle_s_ + o_.dwell_s) AddSettling(since, &a);
    }
    return a;
  }

  // The servo's decaying oscillation `since` seconds after a move ended.
  void AddSettling(double since, Angles* a) const {
    const double env =
        o_.settle_amplitude_rad * std::exp(-since / (0.2 * std::max(settle_s_, 0.05)));
    const double w = 2 * M_PI * 4.0;  // 4 Hz
    const double decay = 1.0 / (0.2 * std::max(settle_s_, 0.05));
    if (gyro_model_ == nullptr) {
      a->value += Eigen::Vector3d::Constant(env * std::sin(w * since));
      a->rate +=
          Eigen::Vector3d::Constant(env * (w * std::cos(w * since) - std::sin(w * since) * decay));
    } else {
      // With a gyro model the rate is continuous too (a real table's is): env (1 - cos)/2
      // starts at rest, where env sin starts at a rate of env w -- a step the moves' integrals
      // would see as an error of half a sample period times it (5e-5 rad at 100 Hz). Sessions
      // without a gyro model keep the old shape and their bytes.
      a->value += Eigen::Vector3d::Constant(env * 0.5 * (1 - std::cos(w * since)));
      a->rate += Eigen::Vector3d::Constant(
          env * 0.5 * (w * std::sin(w * since) - (1 - std::cos(w * since)) * decay));
    }
  }

  // One step of the accelerometer's and magnetometer's drift; their drift at tk (`settle`: the
  // warm-up's remaining fraction), added to the prefix sums.
  void StepDrift(double settle, Eigen::Vector3d* drift_acc, Eigen::Vector3d* drift_mag) {
    Drift& d = drift_;
    for (int i = 0; i < 3; ++i) {
      d.wander_acc[i] =
          d.phi * d.wander_acc[i] + d.drive * c_.acc_bias_instability * random_.Normal();
      d.wander_mag[i] =
          d.phi * d.wander_mag[i] + d.drive * c_.mag_bias_instability * random_.Normal();
      if (d.walk_acc_step > 0) d.walk_acc[i] += d.walk_acc_step * random_.Normal();
      if (d.walk_mag_step > 0) d.walk_mag[i] += d.walk_mag_step * random_.Normal();
    }
    *drift_acc = d.wander_acc + d.walk_acc + settle * d.warm_acc;
    *drift_mag = d.wander_mag + d.walk_mag + settle * d.warm_mag;
    out_.acc_drift_sum.push_back(out_.acc_drift_sum.back() + *drift_acc);
    out_.mag_drift_sum.push_back(out_.mag_drift_sum.back() + *drift_mag);
  }

  // The same for the gyroscope (with a gyro model).
  Eigen::Vector3d StepGyroDrift(double settle) {
    Drift& d = drift_;
    for (int i = 0; i < 3; ++i) {
      d.wander_gyr[i] =
          d.phi * d.wander_gyr[i] + d.drive * c_.gyr_bias_instability * random_.Normal();
      if (d.walk_gyr_step > 0) d.walk_gyr[i] += d.walk_gyr_step * random_.Normal();
    }
    const Eigen::Vector3d drift_gyr = d.wander_gyr + d.walk_gyr + settle * d.warm_gyr;
    out_.gyr_drift_sum.push_back(out_.gyr_drift_sum.back() + drift_gyr);
    return drift_gyr;
  }

  // The lever arm's acceleration in q at angles `a` (zero without one).
  Eigen::Vector3d LeverAcceleration(std::size_t k, const Angles& a) {
    if (o_.lever_arm_q_m.isZero()) return Eigen::Vector3d::Zero();
    const Eigen::Vector3d w = BodyRate(a);
    const Eigen::Vector3d w_dot =
        k > 0 ? Eigen::Vector3d((w - previous_rate_q_) / dt_) : Eigen::Vector3d::Zero();
    previous_rate_q_ = w;
    return w.cross(w.cross(o_.lever_arm_q_m)) + w_dot.cross(o_.lever_arm_q_m);
  }

  // Sample k at tk with the table at `a`: the models' predictions, the drift, the white noise and
  // the quantisation.
  Sample SimulateSample(std::size_t k, double tk, const Angles& a) {
    const TablePose pose{a.value[0], a.value[1], a.value[2]};
    // The parameters now: at the die's temperature with a chamber, else the constant truths.
    const Eigen::VectorXd* acc_theta = &out_.accel_truth;
    const Eigen::VectorXd* mag_theta = &out_.mag_truth;
    const Eigen::VectorXd* gyr_theta = &out_.gyro_truth;
    Eigen::VectorXd acc_at, mag_at, gyr_at;
    double die_c = 0.0;
    if (die_) {
      die_c = die_->Advance(tk);
      die_sum_.push_back(die_sum_.back() + die_c);
      // The parameters at the die's temperature through the hysteresis's play (none: the die's).
      const double param_c = die_->parameter_c();
      param_sum_.push_back(param_sum_.back() + param_c);
      acc_at = out_.accel_thermal->ThetaAt(param_c), acc_theta = &acc_at;
      mag_at = out_.mag_thermal->ThetaAt(param_c), mag_theta = &mag_at;
      if (gyro_model_) gyr_at = out_.gyro_thermal->ThetaAt(param_c), gyr_theta = &gyr_at;
    }
    const double settle = std::exp(-tk / o_.warmup_tau_s);
    Eigen::Vector3d drift_acc, drift_mag;
    StepDrift(settle, &drift_acc, &drift_mag);
    const Eigen::Vector3d lever_q = LeverAcceleration(k, a);
    Eigen::Vector3d gyr;
    if (gyro_model_) {
      const Eigen::Vector3d drift_gyr = StepGyroDrift(settle);
      // The instantaneous inertial rate and specific force in q (with the lever arm's).
      const Mat3<double> C = pose.C_p_q();
      Eigen::Vector3d table_q = BodyRate(a);
      table_q *= 1.0 + o_.gyr_scale_nonlinearity * table_q.norm();
      gyr = gyro_model_->PredictRate(*gyr_theta, C * earth_ned_ + table_q, C * f_ned_ + lever_q) +
            drift_gyr;
    } else {
      gyr = accel_model_.context().mounting * BodyRate(a) + out_.gyro_bias_radps;
    }
    Sample smp;
    smp.t_host_ns = static_cast<std::int64_t>(std::llround(tk * 1e9));
    smp.t_device_s = o_.clock_offset_s + tk * (1.0 + o_.clock_drift_ppm * 1e-6);
    smp.counter = static_cast<std::uint32_t>(k);
    Eigen::Vector3d acc = accel_model_.Predict(*acc_theta, pose) + drift_acc;
    if (!o_.lever_arm_q_m.isZero()) acc += accel_model_.context().mounting * lever_q;
    Eigen::Vector3d mag = mag_model_.Predict(*mag_theta, pose) + drift_mag;
    if (o_.magnet_peak > 0 && tk >= o_.magnet_at_s && tk <= o_.magnet_at_s + o_.magnet_s) {
      // A magnet passing by: a raised cosine over its time.
      const double phase = 2 * M_PI * (tk - o_.magnet_at_s) / o_.magnet_s;
      mag += o_.magnet_peak * 0.5 * (1.0 - std::cos(phase)) * o_.magnet_direction.normalized();
    }
    if (o_.mag_lag_s > 0) {
      // A lagging magnetometer: the field of lag samples before (the first sample's before it).
      const auto lag = static_cast<std::size_t>(std::llround(o_.mag_lag_s * o_.rate_hz));
      mag_lagged_.push_back(mag);
      while (mag_lagged_.size() > lag + 1) mag_lagged_.pop_front();
      mag = mag_lagged_.front();
    }
    if (o_.mag_bandwidth_hz > 0) {
      // The magnetometer's first-order low-pass, started at the first value; with the noise
      // filtered, the noise before it (the draws as below, scaled by sqrt((2 - alpha) / alpha):
      // the filter's output variance is alpha / (2 - alpha) of its input's), quantised after it.
      // A device's filter runs from power-on, long before a capture: it starts in its steady
      // state, the first value's noise at the output's own level (started from one raw draw,
      // its first 50 ms carried 5.6 times the noise, and a chi^2 too large by 1 %).
      const double alpha = 1.0 - std::exp(-2 * M_PI * o_.mag_bandwidth_hz * dt_);
      const double input_scale = std::sqrt((2 - alpha) / alpha);
      const Eigen::Vector3d clean = mag;
      if (o_.mag_noise_filtered) AddWhiteNoise(&acc, &gyr, &mag, input_scale);
      mag_filtered_ = k == 0 ? Eigen::Vector3d(clean + (mag - clean) / input_scale)
                             : Eigen::Vector3d(*mag_filtered_ + alpha * (mag - *mag_filtered_));
      mag = *mag_filtered_;
      if (o_.mag_noise_filtered) {
        for (int i = 0; i < 3; ++i) mag[i] = Quantise(mag[i], c_.mag_quantum);
      }
    }
    if (!(o_.mag_bandwidth_hz > 0 && o_.mag_noise_filtered)) AddWhiteNoise(&acc, &gyr, &mag);
    if (o_.mag_rate_hz > 0 && o_.mag_rate_hz < o_.rate_hz) {
      // Sample and hold: a new value at the magnetometer's own instants (the draws above are made
      // all the same, so that the other triads' noise is as without it).
      const auto update = static_cast<std::int64_t>(std::floor(tk * o_.mag_rate_hz + 1e-9));
      if (update != mag_update_ || !mag_held_) {
        mag_update_ = update;
        mag_held_ = mag;
      }
      mag = *mag_held_;
    }
    smp.acc_mps2 = acc;
    smp.gyr_radps = gyr;
    smp.mag = mag;
    smp.temp_c = die_ ? die_->Reported(die_c) : 25.0 + 0.5 * tk / std::max(out_.duration_s, 1.0);
    return smp;
  }

  // White noise (density x sqrt(rate / 2)) and the ADC's steps, axis by axis; mag_scale > 0: the
  // magnetometer's noise that many times the class's, not quantised (a filter follows).
  void AddWhiteNoise(Eigen::Vector3d* acc, Eigen::Vector3d* gyr, Eigen::Vector3d* mag,
                     double mag_scale = 0.0) {
    const double white_acc = c_.acc_noise_density * std::sqrt(o_.rate_hz / 2.0);
    const double white_gyr = c_.gyr_noise_density * std::sqrt(o_.rate_hz / 2.0);
    const double white_mag = c_.mag_noise_rms * (mag_scale > 0 ? mag_scale : 1.0);
    for (int i = 0; i < 3; ++i) {
      (*acc)[i] = Quantise((*acc)[i] + white_acc * random_.Normal(), c_.acc_quantum);
      (*gyr)[i] = Quantise((*gyr)[i] + white_gyr * random_.Normal(), c_.gyr_quantum);
      (*mag)[i] += white_mag * random_.Normal();
      if (!(mag_scale > 0)) (*mag)[i] = Quantise((*mag)[i], c_.mag_quantum);
    }
  }

  // Each dwell's mean drift, from the prefix sums: the samples with t_s <= k dt < dwell_end_s.
  void SetDwellWanderMeans() {
    const auto first_at_or_after = [&](double at_s) {
      std::size_t lo = 0, hi = out_.samples.size();
      while (lo < hi) {
        const std::size_t mid = (lo + hi) / 2;
        if (static_cast<double>(mid) * dt_ < at_s) {
          lo = mid + 1;
        } else {
          hi = mid;
        }
      }
      return lo;
    };
    for (auto& e : out_.events) {
      const std::size_t a = first_at_or_after(e.t_s), b = first_at_or_after(e.dwell_end_s);
      if (b <= a) continue;
      const double count = static_cast<double>(b - a);
      e.acc_wander_mean = (out_.acc_drift_sum[b] - out_.acc_drift_sum[a]) / count;
      e.mag_wander_mean = (out_.mag_drift_sum[b] - out_.mag_drift_sum[a]) / count;
      if (gyro_model_) {
        e.gyr_wander_mean = (out_.gyr_drift_sum[b] - out_.gyr_drift_sum[a]) / count;
      }
      if (die_) {
        e.die_mean_c = (die_sum_[b] - die_sum_[a]) / count;
        e.parameter_mean_c = (param_sum_[b] - param_sum_[a]) / count;
      }
    }
  }

  const MeasurementModel& accel_model_;
  const MeasurementModel& mag_model_;
  const MeasurementModel* gyro_model_;
  const SessionSimOptions& o_;
  const SensorClass& c_;
  RandomStream random_;
  const double settle_s_;
  const double dt_;
  const Eigen::Vector3d earth_ned_, f_ned_;  // the Earth's rate and the specific force, NED
  SimulatedSession out_;
  std::vector<Segment> segments_;
  Drift drift_;
  Eigen::Vector3d previous_rate_q_ = Eigen::Vector3d::Zero();
  std::optional<sim::HandPath> hand_;
  // The magnetometer's low-pass state and its held value (SessionSimOptions::mag_*).
  std::optional<Eigen::Vector3d> mag_filtered_, mag_held_;
  std::deque<Eigen::Vector3d> mag_lagged_;  // with a lag: the latest fields, oldest first
  std::int64_t mag_update_ = -1;
  // With a chamber: the die's temperature, and its prefix sums per sample.
  std::optional<DieTemperature> die_;
  std::vector<double> die_sum_;
  std::vector<double> param_sum_;  // the parameters' temperature (the hysteresis's play)
};

}  // namespace

SimulatedSession SimulateSession(const MeasurementModel& accel_model,
                                 const MeasurementModel& mag_model,
                                 const std::vector<TablePose>& poses, const SessionSimOptions& o,
                                 const MeasurementModel* gyro_model) {
  return SessionSimulator(accel_model, mag_model, o, gyro_model).Simulate(poses);
}

}  // namespace turncal
