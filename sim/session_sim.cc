#include "sim/session_sim.h"

#include <algorithm>
#include <cmath>

#include "core/estimation/move_integrator.h"

namespace turncal {

bool SessionSimOptions::IsValid(std::string* error) const {
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  if (!(rate_hz > 0 && rate_hz <= 10000)) return fail("rate must be in (0, 10000] Hz");
  if (!(dwell_s > 0) || !(move_s > 0) || !(settle_s >= 0) || !(start_s >= 0)) {
    return fail("dwell and move times must be > 0, settle and start >= 0");
  }
  if (!(sensor.bias_tau_s > 0)) return fail("bias time constant must be > 0");
  if (!lever_arm_q_m.allFinite() || lever_arm_q_m.norm() > 2.0) {
    return fail("the lever arm must be finite and at most 2 m");
  }
  if (!(acc_random_walk >= 0 && mag_random_walk >= 0 && acc_warmup >= 0 && mag_warmup >= 0 &&
        gyr_warmup >= 0)) {
    return fail("random walk and warm-up must be >= 0");
  }
  if (!(warmup_tau_s > 0)) return fail("the warm-up time constant must be > 0");
  if (table && !table->IsValid(error)) return false;
  return true;
}

std::vector<TablePose> DefaultSessionPoses() {
  std::vector<TablePose> poses = CubePoses26();
  const double d = 0.5;
  const Eigen::Vector3d extra[10] = {{1, d, 0},  {-d, 1, 0}, {0, 1, d},   {0, -d, 1}, {d, 0, 1},
                                     {1, 0, -d}, {1, d, d},  {-d, 1, -d}, {d, -d, 1}, {-1, -d, d}};
  for (int i = 0; i < 10; ++i)
    poses.push_back(PoseWithDownAlong(extra[i], (i * 37 % 360) * M_PI / 180));
  return poses;
}

std::vector<TablePose> DefaultRateSegments(double rate_dps, bool two_rates) {
  std::vector<TablePose> out;
  std::vector<double> rates{rate_dps, -rate_dps};
  if (two_rates) rates.insert(rates.end(), {rate_dps / 3, -rate_dps / 3});
  const struct {
    TableAxis axis;
    double gamma_deg;
  } plan[] = {{TableAxis::kInner, 0},
              {TableAxis::kMiddle, 0},
              {TableAxis::kOuter, 0},
              {TableAxis::kOuter, 90}};
  for (double r : rates) {
    for (const auto& p : plan) {
      TablePose pose;
      pose.gamma_rad = p.axis == TableAxis::kMiddle ? 0.0 : p.gamma_deg * M_PI / 180;
      pose.rate_axis = p.axis;
      pose.rate_radps = r * M_PI / 180;
      out.push_back(pose);
    }
  }
  return out;
}

namespace {

// Smooth step 0 -> 1 over [0, 1] with zero rate at both ends: (1 - cos(pi s)) / 2.
double SCurve(double s) { return 0.5 * (1.0 - std::cos(M_PI * s)); }
double SCurveRate(double s) { return 0.5 * M_PI * std::sin(M_PI * s); }
// Smooth step 0 -> 1 with zero rate and zero acceleration at both ends: s - sin(2 pi s) / (2 pi).
double Cycloid(double s) { return s - std::sin(2 * M_PI * s) / (2 * M_PI); }
double CycloidRate(double s) { return 1.0 - std::cos(2 * M_PI * s); }

struct Angles {
  Eigen::Vector3d value = Eigen::Vector3d::Zero();  // phi, gamma, psi
  Eigen::Vector3d rate = Eigen::Vector3d::Zero();
};

Eigen::Vector3d Vec(const TablePose& p) { return {p.phi_rad, p.gamma_rad, p.psi_rad}; }

// Angular rate of the table's inner frame q with respect to p, expressed in q:
// [w x] = -dC/dt C^T for C = C_p^q.
Eigen::Vector3d BodyRate(const Angles& a) {
  const double h = 1e-5;
  const Eigen::Vector3d plus = a.value + h * a.rate, minus = a.value - h * a.rate;
  const Mat3<double> C = C_p_q(a.value[0], a.value[1], a.value[2]);
  const Mat3<double> dC =
      (C_p_q(plus[0], plus[1], plus[2]) - C_p_q(minus[0], minus[1], minus[2])) / (2 * h);
  const Mat3<double> W = -dC * C.transpose();
  return Eigen::Vector3d(W(2, 1) - W(1, 2), W(0, 2) - W(2, 0), W(1, 0) - W(0, 1)) * 0.5;
}

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
  double rate = 0.0, up_s = 0.0, hold_s = 0.0, ripple = 0.0, ripple_hz = 0.0;
  double ripple_phase = 0.0;  // rad, drawn per segment: a table's ripple is not locked to a window

  // The rotating axis's angle and rate `since` seconds after t0.
  std::pair<double, double> AngleRate(double since) const {
    const double a0 = from[spin];
    // Integral of SCurve over [0, u]: u/2 - sin(pi u) / (2 pi).
    const auto ramp = [](double u) { return u / 2 - std::sin(M_PI * u) / (2 * M_PI); };
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

}  // namespace

SimulatedSession SimulateSession(const MeasurementModel& accel_model,
                                 const MeasurementModel& mag_model,
                                 const std::vector<TablePose>& poses, const SessionSimOptions& o,
                                 const MeasurementModel* gyro_model) {
  SimulatedSession out;
  std::mt19937_64 rng(o.seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  const SensorClass& c = o.sensor;
  out.accel_truth = DrawTruth(accel_model, c, &rng);
  out.mag_truth = DrawTruth(mag_model, c, &rng);
  for (int i = 0; i < 3; ++i) out.gyro_bias_radps[i] = c.gyr_turn_on_bias * normal(rng);
  if (gyro_model) {
    out.gyro_truth = DrawTruth(*gyro_model, c, &rng);
    out.gyro_bias_radps = out.gyro_truth.segment<3>(gyro_model->index_of("bx"));
  }

  std::vector<Segment> segments;
  std::mt19937_64 ripple_rng(o.seed ^ 0x51dd1e5ull);
  double t = 0;
  Eigen::Vector3d at = Eigen::Vector3d::Zero();
  segments.push_back({t, t + o.start_s, at, at, false});
  t += o.start_s;
  const double settle_s = o.table ? o.table->settle_s : o.settle_s;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    TablePose goal = poses[i];
    const int spin = SpinIndex(goal.rate_axis);
    if (spin >= 0) {
      // The rotating axis stays where it is while the others move to their angles.
      (spin == 0 ? goal.phi_rad : spin == 1 ? goal.gamma_rad : goal.psi_rad) = at[spin];
    }
    Eigen::Vector3d target = Vec(goal);
    double move_s = o.move_s;
    if (o.table) {
      const TablePose from{at[0], at[1], at[2]};
      target = at + o.table->Travel(from, goal);
      move_s = std::max(o.table->MoveSeconds(from, goal), 0.1);
    }
    segments.push_back({t, t + move_s, at, target, true});
    t += move_s;
    SessionPoseEvent e;
    e.index = static_cast<int>(i);
    e.pose = poses[i];
    if (spin < 0) {
      segments.push_back({t, t + settle_s + o.dwell_s, target, target, false});
      e.t_s = t + settle_s;
      e.dwell_end_s = t + settle_s + o.dwell_s;
      out.events.push_back(e);
      t += settle_s + o.dwell_s;
      at = target;
      continue;
    }
    segments.push_back({t, t + settle_s, target, target, false});
    t += settle_s;
    const double rate = goal.rate_radps;
    const double turn_s = 2 * M_PI / std::abs(rate);
    e.revolutions_s = std::max(1.0, std::ceil(o.dwell_s / turn_s)) * turn_s;
    Segment sp{t, 0.0, target, target, false};
    sp.spin = spin;
    sp.rate = rate;
    sp.up_s = o.spin_s;
    sp.hold_s = o.rate_settle_s + e.revolutions_s + 2.0;
    sp.ripple = o.rate_ripple;
    sp.ripple_hz = o.ripple_hz;
    // The ripple's phase at the hold's start, from its own stream (the session's stays as it was):
    // locked to the hold it made the same error of up to 4e-6 of the rate in every session's
    // segments (2 pi f T apart), which the Monte Carlo saw as a scale bias of 0.2 sigma.
    sp.ripple_phase = std::uniform_real_distribution<double>(0.0, 2 * M_PI)(ripple_rng);
    sp.t1 = t + 2 * sp.up_s + sp.hold_s;
    sp.to[spin] = sp.AngleRate(sp.t1 - sp.t0).first;
    segments.push_back(sp);
    e.t_s = t + sp.up_s + o.rate_settle_s;
    e.dwell_end_s = e.t_s + e.revolutions_s;
    out.events.push_back(e);
    t = sp.t1;
    at = sp.to;
  }
  out.duration_s = t;

  const double dt = 1.0 / o.rate_hz;
  const double white_acc = c.acc_noise_density * std::sqrt(o.rate_hz / 2.0);
  const double white_gyr = c.gyr_noise_density * std::sqrt(o.rate_hz / 2.0);
  const double white_mag = c.mag_noise_rms;
  const double phi = std::exp(-dt / c.bias_tau_s);
  const double drive = std::sqrt(1.0 - phi * phi);
  Eigen::Vector3d wander_acc, wander_mag, wander_gyr = Eigen::Vector3d::Zero();
  for (int i = 0; i < 3; ++i) {
    wander_acc[i] = c.acc_bias_instability * normal(rng);
    wander_mag[i] = c.mag_bias_instability * normal(rng);
  }
  Eigen::Vector3d walk_gyr = Eigen::Vector3d::Zero();
  const double walk_gyr_step = o.gyr_random_walk * std::sqrt(dt);
  const Eigen::Vector3d earth_ned = EarthRateNed(accel_model.context().reference);
  const Eigen::Vector3d f_ned = SpecificForceNed(accel_model.context().reference);
  if (gyro_model) {
    for (int i = 0; i < 3; ++i) wander_gyr[i] = c.gyr_bias_instability * normal(rng);
  }
  // Random walk and warm-up (drawn only when asked for, so that sessions without them keep the
  // random stream, and the bytes, they had).
  Eigen::Vector3d walk_acc = Eigen::Vector3d::Zero(), walk_mag = Eigen::Vector3d::Zero();
  Eigen::Vector3d warm_acc = Eigen::Vector3d::Zero(), warm_mag = Eigen::Vector3d::Zero();
  const double walk_acc_step = o.acc_random_walk * std::sqrt(dt);
  const double walk_mag_step = o.mag_random_walk * std::sqrt(dt);
  Eigen::Vector3d warm_gyr = Eigen::Vector3d::Zero();
  for (int i = 0; i < 3; ++i) {
    if (o.acc_warmup > 0) warm_acc[i] = o.acc_warmup * normal(rng);
    if (o.mag_warmup > 0) warm_mag[i] = o.mag_warmup * normal(rng);
  }
  if (gyro_model && o.gyr_warmup > 0) {
    for (int i = 0; i < 3; ++i) warm_gyr[i] = o.gyr_warmup * normal(rng);
  }
  const auto n = static_cast<std::size_t>(std::floor(out.duration_s * o.rate_hz));
  out.samples.reserve(n);
  out.acc_drift_sum.assign(1, Eigen::Vector3d::Zero());
  out.mag_drift_sum.assign(1, Eigen::Vector3d::Zero());
  if (gyro_model) out.gyr_drift_sum.assign(1, Eigen::Vector3d::Zero());
  out.acc_drift_sum.reserve(n + 1);
  out.mag_drift_sum.reserve(n + 1);
  std::size_t seg = 0;
  Eigen::Vector3d previous_rate_q = Eigen::Vector3d::Zero();
  for (std::size_t k = 0; k < n; ++k) {
    const double tk = static_cast<double>(k) * dt;
    while (seg + 1 < segments.size() && tk >= segments[seg].t1) ++seg;
    const Segment& s = segments[seg];
    Angles a;
    if (s.spin >= 0) {
      a.value = s.from;
      const auto [angle, rate] = s.AngleRate(tk - s.t0);
      a.value[s.spin] = angle;
      a.rate[s.spin] = rate;
    } else if (s.moving) {
      const double u = (tk - s.t0) / (s.t1 - s.t0);
      if (gyro_model == nullptr) {
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
      if (seg > 0 && since < settle_s + o.dwell_s) {
        const double env =
            o.settle_amplitude_rad * std::exp(-since / (0.2 * std::max(settle_s, 0.05)));
        const double w = 2 * M_PI * 4.0;  // 4 Hz
        const double decay = 1.0 / (0.2 * std::max(settle_s, 0.05));
        if (gyro_model == nullptr) {
          a.value += Eigen::Vector3d::Constant(env * std::sin(w * since));
          a.rate += Eigen::Vector3d::Constant(
              env * (w * std::cos(w * since) - std::sin(w * since) * decay));
        } else {
          // With a gyro model the rate is continuous too (a real table's is): env (1 - cos)/2
          // starts at rest, where env sin starts at a rate of env w -- a step the moves' integrals
          // would see as an error of half a sample period times it (5e-5 rad at 100 Hz). Sessions
          // without a gyro model keep the old shape and their bytes.
          a.value += Eigen::Vector3d::Constant(env * 0.5 * (1 - std::cos(w * since)));
          a.rate += Eigen::Vector3d::Constant(
              env * 0.5 * (w * std::sin(w * since) - (1 - std::cos(w * since)) * decay));
        }
      }
    }
    const TablePose pose{a.value[0], a.value[1], a.value[2]};
    for (int i = 0; i < 3; ++i) {
      wander_acc[i] = phi * wander_acc[i] + drive * c.acc_bias_instability * normal(rng);
      wander_mag[i] = phi * wander_mag[i] + drive * c.mag_bias_instability * normal(rng);
      if (walk_acc_step > 0) walk_acc[i] += walk_acc_step * normal(rng);
      if (walk_mag_step > 0) walk_mag[i] += walk_mag_step * normal(rng);
    }
    const double settle = std::exp(-tk / o.warmup_tau_s);
    const Eigen::Vector3d drift_acc = wander_acc + walk_acc + settle * warm_acc;
    const Eigen::Vector3d drift_mag = wander_mag + walk_mag + settle * warm_mag;
    out.acc_drift_sum.push_back(out.acc_drift_sum.back() + drift_acc);
    out.mag_drift_sum.push_back(out.mag_drift_sum.back() + drift_mag);
    // The lever arm's acceleration in q (zero without one).
    Eigen::Vector3d lever_q = Eigen::Vector3d::Zero();
    if (!o.lever_arm_q_m.isZero()) {
      const Eigen::Vector3d w = BodyRate(a);
      const Eigen::Vector3d w_dot =
          k > 0 ? Eigen::Vector3d((w - previous_rate_q) / dt) : Eigen::Vector3d::Zero();
      lever_q = w.cross(w.cross(o.lever_arm_q_m)) + w_dot.cross(o.lever_arm_q_m);
      previous_rate_q = w;
    }
    Eigen::Vector3d gyr;
    if (gyro_model) {
      for (int i = 0; i < 3; ++i) {
        wander_gyr[i] = phi * wander_gyr[i] + drive * c.gyr_bias_instability * normal(rng);
        if (walk_gyr_step > 0) walk_gyr[i] += walk_gyr_step * normal(rng);
      }
      const Eigen::Vector3d drift_gyr = wander_gyr + walk_gyr + settle * warm_gyr;
      out.gyr_drift_sum.push_back(out.gyr_drift_sum.back() + drift_gyr);
      // The instantaneous inertial rate and specific force in q (with the lever arm's).
      const Mat3<double> C = pose.C_p_q();
      Eigen::Vector3d table_q = BodyRate(a);
      table_q *= 1.0 + o.gyr_scale_nonlinearity * table_q.norm();
      gyr = gyro_model->PredictRate(out.gyro_truth, C * earth_ned + table_q, C * f_ned + lever_q) +
            drift_gyr;
    } else {
      gyr = accel_model.context().mounting * BodyRate(a) + out.gyro_bias_radps;
    }
    Sample smp;
    smp.t_host_ns = static_cast<std::int64_t>(std::llround(tk * 1e9));
    smp.t_device_s = o.clock_offset_s + tk * (1.0 + o.clock_drift_ppm * 1e-6);
    smp.counter = static_cast<std::uint32_t>(k);
    Eigen::Vector3d acc = accel_model.Predict(out.accel_truth, pose) + drift_acc;
    if (!o.lever_arm_q_m.isZero()) acc += accel_model.context().mounting * lever_q;
    Eigen::Vector3d mag = mag_model.Predict(out.mag_truth, pose) + drift_mag;
    for (int i = 0; i < 3; ++i) {
      acc[i] = Quantise(acc[i] + white_acc * normal(rng), c.acc_quantum);
      gyr[i] = Quantise(gyr[i] + white_gyr * normal(rng), c.gyr_quantum);
      mag[i] = Quantise(mag[i] + white_mag * normal(rng), c.mag_quantum);
    }
    smp.acc_mps2 = acc;
    smp.gyr_radps = gyr;
    smp.mag = mag;
    smp.temp_c = 25.0 + 0.5 * tk / std::max(out.duration_s, 1.0);
    out.samples.push_back(smp);
  }
  // Each dwell's mean drift, from the prefix sums: the samples with t_s <= k dt < dwell_end_s.
  const auto first_at_or_after = [&](double at_s) {
    std::size_t lo = 0, hi = out.samples.size();
    while (lo < hi) {
      const std::size_t mid = (lo + hi) / 2;
      if (static_cast<double>(mid) * dt < at_s) {
        lo = mid + 1;
      } else {
        hi = mid;
      }
    }
    return lo;
  };
  for (auto& e : out.events) {
    const std::size_t a = first_at_or_after(e.t_s), b = first_at_or_after(e.dwell_end_s);
    if (b <= a) continue;
    const double count = static_cast<double>(b - a);
    e.acc_wander_mean = (out.acc_drift_sum[b] - out.acc_drift_sum[a]) / count;
    e.mag_wander_mean = (out.mag_drift_sum[b] - out.mag_drift_sum[a]) / count;
    if (gyro_model) e.gyr_wander_mean = (out.gyr_drift_sum[b] - out.gyr_drift_sum[a]) / count;
  }
  return out;
}

Eigen::Vector3d SimulatedSession::EffectiveAccBiasOffset() const {
  Eigen::Vector3d m = Eigen::Vector3d::Zero();
  for (const auto& e : events) m += e.acc_wander_mean;
  return events.empty() ? m : Eigen::Vector3d(m / static_cast<double>(events.size()));
}

namespace {

Eigen::Vector3d WindowMean(const std::vector<Sample>& samples,
                           const std::vector<Eigen::Vector3d>& sums, double t0_s, double t1_s) {
  if (sums.size() != samples.size() + 1) return Eigen::Vector3d::Zero();
  const auto at = [&](double t) {
    return static_cast<std::size_t>(
        std::lower_bound(
            samples.begin(), samples.end(), t,
            [](const Sample& s, double v) { return static_cast<double>(s.t_host_ns) * 1e-9 < v; }) -
        samples.begin());
  };
  const std::size_t a = at(t0_s), b = std::max(a, at(t1_s));
  if (b == a) return Eigen::Vector3d::Zero();
  return (sums[b] - sums[a]) / static_cast<double>(b - a);
}

}  // namespace

Eigen::Vector3d SimulatedSession::AccDriftMean(double t0_s, double t1_s) const {
  return WindowMean(samples, acc_drift_sum, t0_s, t1_s);
}

Eigen::Vector3d SimulatedSession::MagDriftMean(double t0_s, double t1_s) const {
  return WindowMean(samples, mag_drift_sum, t0_s, t1_s);
}

Eigen::Vector3d SimulatedSession::GyrDriftMean(double t0_s, double t1_s) const {
  return WindowMean(samples, gyr_drift_sum, t0_s, t1_s);
}

Eigen::Vector3d SimulatedSession::LastPoseAccBiasOffset() const {
  return events.empty() ? Eigen::Vector3d::Zero() : events.back().acc_wander_mean;
}

Eigen::Vector3d SimulatedSession::LastPoseMagBiasOffset() const {
  return events.empty() ? Eigen::Vector3d::Zero() : events.back().mag_wander_mean;
}

Eigen::Vector3d SimulatedSession::EffectiveMagBiasOffset() const {
  Eigen::Vector3d m = Eigen::Vector3d::Zero();
  for (const auto& e : events) m += e.mag_wander_mean;
  return events.empty() ? m : Eigen::Vector3d(m / static_cast<double>(events.size()));
}

}  // namespace turncal

namespace turncal {

PoseRecord DwellRecord(const SimulatedSession& session, const SessionPoseEvent& event,
                       SensorKind sensor) {
  TriadStats stats;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  Eigen::Matrix3d sum2 = Eigen::Matrix3d::Zero();
  for (const auto& s : session.samples) {
    const double t = static_cast<double>(s.t_host_ns) * 1e-9;
    if (t < event.t_s || t >= event.dwell_end_s) continue;
    const auto& v = sensor == SensorKind::kAccelerometer ? s.acc_mps2
                    : sensor == SensorKind::kGyroscope   ? s.gyr_radps
                                                         : s.mag;
    if (!v) continue;
    sum += *v;
    sum2 += *v * v->transpose();
    ++stats.count;
  }
  PoseRecord r;
  r.pose = event.pose;
  r.t_start_s = event.t_s;
  r.t_end_s = event.dwell_end_s;
  if (stats.count > 1) {
    const double n = static_cast<double>(stats.count);
    stats.mean = sum / n;
    stats.covariance = (sum2 - n * stats.mean * stats.mean.transpose()) / (n - 1);
    (sensor == SensorKind::kAccelerometer ? r.acc
     : sensor == SensorKind::kGyroscope   ? r.gyr
                                          : r.mag) = stats;
  }
  return r;
}

}  // namespace turncal

namespace turncal {

MoveRecord MoveBetween(const SimulatedSession& session, const SessionPoseEvent& from,
                       const SessionPoseEvent& to, double rate_hz, double block_s) {
  MoveIntegrator integrator(1.0 / rate_hz, block_s);
  for (const auto& s : session.samples) {
    const double t = static_cast<double>(s.t_host_ns) * 1e-9;
    if (t < from.dwell_end_s || t >= to.t_s || !s.gyr_radps) continue;
    integrator.Add(t, *s.gyr_radps, s.acc_mps2);
  }
  return integrator.Finish(from.pose, to.pose);
}

}  // namespace turncal
