#include "sim/session_sim.h"

#include <algorithm>
#include <cmath>

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
  if (!(acc_random_walk >= 0 && mag_random_walk >= 0 && acc_warmup >= 0 && mag_warmup >= 0)) {
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

namespace {

// Smooth step 0 -> 1 over [0, 1] with zero rate at both ends: (1 - cos(pi s)) / 2.
double SCurve(double s) { return 0.5 * (1.0 - std::cos(M_PI * s)); }
double SCurveRate(double s) { return 0.5 * M_PI * std::sin(M_PI * s); }

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

}  // namespace

SimulatedSession SimulateSession(const MeasurementModel& accel_model,
                                 const MeasurementModel& mag_model,
                                 const std::vector<TablePose>& poses, const SessionSimOptions& o) {
  SimulatedSession out;
  std::mt19937_64 rng(o.seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  const SensorClass& c = o.sensor;
  out.accel_truth = DrawTruth(accel_model, c, &rng);
  out.mag_truth = DrawTruth(mag_model, c, &rng);
  for (int i = 0; i < 3; ++i) out.gyro_bias_radps[i] = c.gyr_turn_on_bias * normal(rng);

  // The schedule: segments of (start, end, from, to, kind).
  struct Segment {
    double t0, t1;
    Eigen::Vector3d from, to;
    bool moving;
  };
  std::vector<Segment> segments;
  double t = 0;
  Eigen::Vector3d at = Eigen::Vector3d::Zero();
  segments.push_back({t, t + o.start_s, at, at, false});
  t += o.start_s;
  const double settle_s = o.table ? o.table->settle_s : o.settle_s;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    Eigen::Vector3d target = Vec(poses[i]);
    double move_s = o.move_s;
    if (o.table) {
      const TablePose from{at[0], at[1], at[2]};
      target = at + o.table->Travel(from, poses[i]);
      move_s = std::max(o.table->MoveSeconds(from, poses[i]), 0.1);
    }
    segments.push_back({t, t + move_s, at, target, true});
    t += move_s;
    segments.push_back({t, t + settle_s + o.dwell_s, target, target, false});
    SessionPoseEvent e;
    e.t_s = t + settle_s;
    e.index = static_cast<int>(i);
    e.pose = poses[i];
    e.dwell_end_s = t + settle_s + o.dwell_s;
    out.events.push_back(e);
    t += settle_s + o.dwell_s;
    at = target;
  }
  out.duration_s = t;

  const double dt = 1.0 / o.rate_hz;
  const double white_acc = c.acc_noise_density * std::sqrt(o.rate_hz / 2.0);
  const double white_gyr = c.gyr_noise_density * std::sqrt(o.rate_hz / 2.0);
  const double white_mag = c.mag_noise_rms;
  const double phi = std::exp(-dt / c.bias_tau_s);
  const double drive = std::sqrt(1.0 - phi * phi);
  Eigen::Vector3d wander_acc, wander_mag;
  for (int i = 0; i < 3; ++i) {
    wander_acc[i] = c.acc_bias_instability * normal(rng);
    wander_mag[i] = c.mag_bias_instability * normal(rng);
  }
  // Random walk and warm-up (drawn only when asked for, so that sessions without them keep the
  // random stream, and the bytes, they had).
  Eigen::Vector3d walk_acc = Eigen::Vector3d::Zero(), walk_mag = Eigen::Vector3d::Zero();
  Eigen::Vector3d warm_acc = Eigen::Vector3d::Zero(), warm_mag = Eigen::Vector3d::Zero();
  const double walk_acc_step = o.acc_random_walk * std::sqrt(dt);
  const double walk_mag_step = o.mag_random_walk * std::sqrt(dt);
  for (int i = 0; i < 3; ++i) {
    if (o.acc_warmup > 0) warm_acc[i] = o.acc_warmup * normal(rng);
    if (o.mag_warmup > 0) warm_mag[i] = o.mag_warmup * normal(rng);
  }
  const auto n = static_cast<std::size_t>(std::floor(out.duration_s * o.rate_hz));
  out.samples.reserve(n);
  out.acc_drift_sum.assign(1, Eigen::Vector3d::Zero());
  out.mag_drift_sum.assign(1, Eigen::Vector3d::Zero());
  out.acc_drift_sum.reserve(n + 1);
  out.mag_drift_sum.reserve(n + 1);
  std::size_t seg = 0;
  for (std::size_t k = 0; k < n; ++k) {
    const double tk = static_cast<double>(k) * dt;
    while (seg + 1 < segments.size() && tk >= segments[seg].t1) ++seg;
    const Segment& s = segments[seg];
    Angles a;
    if (s.moving) {
      const double u = (tk - s.t0) / (s.t1 - s.t0);
      a.value = s.from + (s.to - s.from) * SCurve(u);
      a.rate = (s.to - s.from) * SCurveRate(u) / (s.t1 - s.t0);
    } else {
      a.value = s.to;
      // A decaying oscillation after a move (the table's servo settling).
      const double since = tk - s.t0;
      if (seg > 0 && since < settle_s + o.dwell_s) {
        const double env =
            o.settle_amplitude_rad * std::exp(-since / (0.2 * std::max(settle_s, 0.05)));
        const double w = 2 * M_PI * 4.0;  // 4 Hz
        a.value += Eigen::Vector3d::Constant(env * std::sin(w * since));
        a.rate += Eigen::Vector3d::Constant(
            env *
            (w * std::cos(w * since) - std::sin(w * since) / (0.2 * std::max(settle_s, 0.05))));
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
    Sample smp;
    smp.t_host_ns = static_cast<std::int64_t>(std::llround(tk * 1e9));
    smp.t_device_s = o.clock_offset_s + tk * (1.0 + o.clock_drift_ppm * 1e-6);
    smp.counter = static_cast<std::uint32_t>(k);
    Eigen::Vector3d acc = accel_model.Predict(out.accel_truth, pose) + drift_acc;
    Eigen::Vector3d mag = mag_model.Predict(out.mag_truth, pose) + drift_mag;
    Eigen::Vector3d gyr = accel_model.context().mounting * BodyRate(a) + out.gyro_bias_radps;
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
  const bool accel = sensor == SensorKind::kAccelerometer;
  TriadStats stats;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  Eigen::Matrix3d sum2 = Eigen::Matrix3d::Zero();
  for (const auto& s : session.samples) {
    const double t = static_cast<double>(s.t_host_ns) * 1e-9;
    if (t < event.t_s || t >= event.dwell_end_s) continue;
    const auto& v = accel ? s.acc_mps2 : s.mag;
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
    (accel ? r.acc : r.mag) = stats;
  }
  return r;
}

}  // namespace turncal
