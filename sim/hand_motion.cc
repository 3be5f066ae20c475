#include "sim/hand_motion.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "sim/table_kinematics.h"

namespace turncal::sim {

bool HandMotion::IsValid(std::string* error) const {
  auto fail = [&](std::string why) {
    if (error) *error = std::move(why);
    return false;
  };
  if (!(duration_s > 0 && std::isfinite(duration_s)))
    return fail("the hand's motion needs a duration > 0 s");
  if (!(rate_dps > 0 && rate_dps <= 2000)) {
    return fail(fmt::format("the hand's rate {} deg/s: give 0 < rate <= 2000", rate_dps));
  }
  if (!(pause_every_s >= 0) || !(pause_s >= 0) || !(ramp_s > 0)) {
    return fail("the hand's pauses: every >= 0 s, pause >= 0 s, ramp > 0 s");
  }
  if (pause_every_s > 0 && pause_s < 2 * ramp_s) {
    return fail(fmt::format("a pause of {} s cannot hold its two ramps of {} s", pause_s, ramp_s));
  }
  return true;
}

bool HandPathByName(const std::string& name, HandMotion::Path* path) {
  if (name == "tumble") {
    *path = HandMotion::Path::kTumble;
  } else if (name == "figure8") {
    *path = HandMotion::Path::kFigureEight;
  } else if (name == "planar") {
    *path = HandMotion::Path::kPlanar;
  } else {
    return false;
  }
  return true;
}

const char* HandPathName(HandMotion::Path path) {
  switch (path) {
    case HandMotion::Path::kTumble:
      return "tumble";
    case HandMotion::Path::kFigureEight:
      return "figure8";
    case HandMotion::Path::kPlanar:
      return "planar";
  }
  return "tumble";
}

HandPath::HandPath(const HandMotion& motion, std::uint64_t seed) : motion_(motion) {
  std::mt19937_64 rng(seed ^ 0x4a4d0e5ull);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const auto sign = [&] { return u(rng) < 0.5 ? -1.0 : 1.0; };
  const auto wave = [&](int axis, int k, double amplitude, double w_lo, double w_hi) {
    amplitude_[axis][k] = amplitude;
    omega_[axis][k] = w_lo + (w_hi - w_lo) * u(rng);
    phase_[axis][k] = 2 * M_PI * u(rng);
  };
  switch (motion.path) {
    case HandMotion::Path::kTumble:
      drift_ = Eigen::Vector3d(sign() * (0.8 + 0.4 * u(rng)), 0.0, sign() * (0.5 + 0.4 * u(rng)));
      wave(0, 0, 0.6, 0.5, 1.5), wave(0, 1, 0.3, 1.5, 3.0);
      wave(1, 0, 1.0, 0.4, 1.0), wave(1, 1, 0.3, 1.5, 3.0);
      wave(2, 0, 0.6, 0.5, 1.5), wave(2, 1, 0.3, 1.5, 3.0);
      break;
    case HandMotion::Path::kFigureEight:
      // The figure: phi at 1, psi at 2 (rad per unit of u), locked in phase; gamma wobbles, and
      // psi precesses slowly so that the figure's heading turns.
      drift_ = Eigen::Vector3d(0.0, 0.0, sign() * 0.15);
      amplitude_[0][0] = 1.2, omega_[0][0] = 1.0, phase_[0][0] = 2 * M_PI * u(rng);
      amplitude_[2][0] = 0.9, omega_[2][0] = 2.0, phase_[2][0] = 2 * phase_[0][0];
      wave(1, 0, 0.5, 0.2, 0.4);
      break;
    case HandMotion::Path::kPlanar:
      drift_ = Eigen::Vector3d(0.0, 0.0, sign());
      break;
  }
  // The body rate's RMS over a long stretch of the path at unit scale.
  double sum = 0;
  const int n = 4000;
  for (int i = 0; i < n; ++i) {
    Eigen::Vector3d a, r;
    Shape(200.0 * i / n, &a, &r);
    sum += TableBodyRate(a, r).squaredNorm();
  }
  scale_ = motion.rate_dps * M_PI / 180 / std::sqrt(sum / n);
}

void HandPath::Shape(double u, Eigen::Vector3d* angles, Eigen::Vector3d* rates) const {
  for (int i = 0; i < 3; ++i) {
    double a = drift_[i] * u, r = drift_[i];
    for (int k = 0; k < 2; ++k) {
      a += amplitude_[i][k] * std::sin(omega_[i][k] * u + phase_[i][k]);
      r += amplitude_[i][k] * omega_[i][k] * std::cos(omega_[i][k] * u + phase_[i][k]);
    }
    (*angles)[i] = a;
    (*rates)[i] = r;
  }
}

double HandPath::Speed(double since) const {
  const double D = motion_.duration_s, r = std::min(motion_.ramp_s, D / 2);
  if (since <= 0 || since >= D) return 0.0;
  // 1 less what each ramp and pause takes away (MotionTime integrates exactly this).
  double lost = 0.0;
  if (since < r) lost += 1.0 - SCurve(since / r);
  if (since > D - r) lost += 1.0 - SCurve((D - since) / r);
  const double P = motion_.pause_every_s, L = motion_.pause_s;
  if (P > 0 && L > 0) {
    const double cycle = P + L;
    const double tau = since - std::floor(since / cycle) * cycle - P;  // into the pause
    if (tau >= 0) {
      const double q = std::min(motion_.ramp_s, L / 2);
      lost += tau < q ? SCurve(tau / q) : tau > L - q ? SCurve((L - tau) / q) : 1.0;
    }
  }
  return std::max(0.0, 1.0 - lost);
}

double HandPath::MotionTime(double since) const {
  const double D = motion_.duration_s, r = std::min(motion_.ramp_s, D / 2);
  const double t = std::clamp(since, 0.0, D);
  // The integral of Speed: the start's ramp and the end's lose half a ramp each, a pause its
  // length less one ramp.
  double lost = t < r ? t - r * SCurveIntegral(t / r) : r / 2;
  if (t > D - r) lost += (t - D + r) - r / 2 + r * SCurveIntegral((D - t) / r);
  const double P = motion_.pause_every_s, L = motion_.pause_s;
  if (P > 0 && L > 0) {
    const double cycle = P + L;
    const double q = std::min(motion_.ramp_s, L / 2);
    const auto pause_lost = [&](double tau) {  // lost in a pause tau seconds into it
      if (tau <= 0) return 0.0;
      if (tau < q) return q * SCurveIntegral(tau / q);
      if (tau <= L - q) return q / 2 + (tau - q);
      const double end = std::min(tau, L);
      return q / 2 + (L - 2 * q) + (q / 2 - q * SCurveIntegral((L - end) / q));
    };
    const double whole = std::floor(t / cycle);
    lost += whole * pause_lost(L) + pause_lost(t - whole * cycle - P);
  }
  return t - lost;
}

void HandPath::At(double since, Eigen::Vector3d* angles, Eigen::Vector3d* rates) const {
  const double u = MotionTime(since) * scale_;
  Eigen::Vector3d r;
  Shape(u, angles, &r);
  *rates = r * (scale_ * Speed(since));
}

}  // namespace turncal::sim
