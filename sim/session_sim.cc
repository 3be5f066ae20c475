#include "sim/session_sim.h"

#include <algorithm>
#include <cmath>
#include <limits>

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
  if (chamber && !chamber->IsValid(error)) return false;
  if (chamber && !die.IsValid(error)) return false;
  if (hand && !hand->IsValid(error)) return false;
  if (hand && chamber) return fail("a hand's motion in a chamber is not simulated");
  if (!(mag_rate_hz >= 0 && mag_bandwidth_hz >= 0)) {
    return fail("the magnetometer's rate and bandwidth must be >= 0");
  }
  if (!(mag_lag_s >= 0 && mag_lag_s <= 1.0)) {
    return fail("the magnetometer's lag must be in [0, 1] s");
  }
  if (!(magnet_peak >= 0 && magnet_s > 0 && magnet_direction.norm() > 0)) {
    return fail("a magnet needs a peak >= 0, a duration > 0 and a direction");
  }
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
  if (b == a) {
    // No sample inside (a window one sample period long, shifted by a clock's microseconds):
    // the drift at the sample nearest the window's middle, not nothing.
    if (samples.empty()) return Eigen::Vector3d::Zero();
    const double mid = 0.5 * (t0_s + t1_s);
    std::size_t k = std::min(a, samples.size() - 1);
    if (k > 0 && std::abs(static_cast<double>(samples[k - 1].t_host_ns) * 1e-9 - mid) <
                     std::abs(static_cast<double>(samples[k].t_host_ns) * 1e-9 - mid)) {
      --k;
    }
    return sums[k + 1] - sums[k];
  }
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
  double temp_sum = 0.0, temp_sum2 = 0.0;
  double temp_min = std::numeric_limits<double>::infinity(), temp_max = -temp_min;
  std::int64_t temp_n = 0;
  for (const auto& s : session.samples) {
    const double t = static_cast<double>(s.t_host_ns) * 1e-9;
    if (t < event.t_s || t >= event.dwell_end_s) continue;
    const auto& v = sensor == SensorKind::kAccelerometer ? s.acc_mps2
                    : sensor == SensorKind::kGyroscope   ? s.gyr_radps
                                                         : s.mag;
    if (s.temp_c) {
      temp_sum += *s.temp_c;
      temp_sum2 += *s.temp_c * *s.temp_c;
      temp_min = std::min(temp_min, *s.temp_c);
      temp_max = std::max(temp_max, *s.temp_c);
      ++temp_n;
    }
    if (!v) continue;
    sum += *v;
    sum2 += *v * v->transpose();
    ++stats.count;
  }
  PoseRecord r;
  r.pose = event.pose;
  r.t_start_s = event.t_s;
  r.t_end_s = event.dwell_end_s;
  if (temp_n > 0) {
    const double n = static_cast<double>(temp_n);
    r.temp_c = temp_sum / n;
    const double var =
        temp_n > 1 ? std::max(0.0, (temp_sum2 - n * *r.temp_c * *r.temp_c) / (n - 1)) : 0.0;
    r.temp_spread = TemperatureSpread{std::sqrt(var), temp_min, temp_max};
  }
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
