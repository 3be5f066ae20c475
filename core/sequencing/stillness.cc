#include "core/sequencing/stillness.h"

#include <fmt/format.h>

#include <algorithm>
#include <boost/math/distributions/chi_squared.hpp>
#include <boost/math/distributions/fisher_f.hpp>
#include <boost/math/distributions/normal.hpp>
#include <boost/math/distributions/students_t.hpp>
#include <cmath>

#include "core/sequencing/stillness_stats.h"
#include "core/sequencing/triad_accumulator.h"

namespace turncal {

using namespace stillness_stats;  // NOLINT(build/namespaces): shared with noise_meter.cc

int TriadOfSensor(SensorKind kind) {
  switch (kind) {
    case SensorKind::kAccelerometer:
      return kTriadAcc;
    case SensorKind::kGyroscope:
      return kTriadGyr;
    case SensorKind::kMagnetometer:
      return kTriadMag;
  }
  return kTriadAcc;
}

const char* TriadName(int triad) {
  static const char* const kNames[] = {"acc", "gyr", "mag"};
  return triad >= 0 && triad < 3 ? kNames[triad] : "?";
}

const char* TriadUnit(int triad) {
  static const char* const kUnits[] = {"m/s^2", "rad/s", "(device unit)"};
  return triad >= 0 && triad < 3 ? kUnits[triad] : "";
}

StillSample ToStillSample(const Sample& s) {
  StillSample out;
  out.t_host_ns = s.t_host_ns;
  out.t_device_s = s.t_device_s;
  out.counter = s.counter;
  if (s.acc_mps2) out.v[kTriadAcc] = *s.acc_mps2, out.present |= 1u << kTriadAcc;
  if (s.gyr_radps) out.v[kTriadGyr] = *s.gyr_radps, out.present |= 1u << kTriadGyr;
  if (s.mag) out.v[kTriadMag] = *s.mag, out.present |= 1u << kTriadMag;
  if (s.temp_c) out.temp_c = *s.temp_c;
  out.flags = s.flags;
  return out;
}

bool NoiseProfile::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!(rate_hz > 0) || !std::isfinite(rate_hz)) return fail("the sample rate must be > 0");
  if (!sigma[kTriadAcc] && !sigma[kTriadGyr] && !sigma[kTriadMag]) {
    return fail("stillness needs the noise of at least one triad");
  }
  for (int t = 0; t < 3; ++t) {
    if (sigma[t] && !(sigma[t]->minCoeff() > 0 && sigma[t]->allFinite())) {
      return fail(fmt::format("the {} noise must be finite and > 0", TriadName(t)));
    }
  }
  if (!(gyr_bias_sigma_radps >= 0) || !gyr_bias_radps.allFinite()) {
    return fail("the gyro bias and its sigma must be finite");
  }
  if (!(sigma_dof > 2)) return fail("the noise estimate needs more than 2 degrees of freedom");
  return true;
}

double NoiseProfile::TriadDof(int t) const {
  return sigma_dof * Ar1DofShare(lag_one[static_cast<std::size_t>(t)]);
}

std::string NoiseProfile::Describe() const {
  std::string out = fmt::format("{} at {:.1f} Hz:", source, rate_hz);
  for (int t = 0; t < 3; ++t) {
    if (!sigma[t]) continue;
    out += fmt::format(" {} sigma [{:.3g} {:.3g} {:.3g}] {};", TriadName(t), sigma[t]->x(),
                       sigma[t]->y(), sigma[t]->z(), TriadUnit(t));
  }
  out += fmt::format(" gyro bias [{:.3g} {:.3g} {:.3g}] +- {:.2g} rad/s", gyr_bias_radps.x(),
                     gyr_bias_radps.y(), gyr_bias_radps.z(), gyr_bias_sigma_radps);
  return out;
}

NoiseProfile NoiseProfileForClass(const SensorClass& c, double rate_hz, bool use_mag) {
  NoiseProfile p;
  const double white = std::sqrt(rate_hz / 2.0);
  auto sigma = [&](double density_or_rms, double quantum) {
    return Eigen::Vector3d::Constant(
        std::sqrt(density_or_rms * density_or_rms + quantum * quantum / 12.0));
  };
  p.sigma[kTriadAcc] = sigma(c.acc_noise_density * white, c.acc_quantum);
  p.sigma[kTriadGyr] = sigma(c.gyr_noise_density * white, c.gyr_quantum);
  if (use_mag) p.sigma[kTriadMag] = sigma(c.mag_noise_rms, c.mag_quantum);
  p.gyr_bias_sigma_radps = c.gyr_turn_on_bias;
  p.rate_hz = rate_hz;
  p.device_period_s = 1.0 / rate_hz;
  p.source = fmt::format("configured from the {} class", c.name);
  return p;
}

bool StillnessOptions::IsValid(std::string* error) const {
  if (!(window_s > 0 && window_s <= 10) || !(false_alarm > 0 && false_alarm < 0.5) ||
      !(outlier_k >= 3) || !(gyr_bias_drift_radps >= 0) || !(gyr_bias_tempco_radps_per_c >= 0)) {
    if (error) {
      *error =
          "stillness: window must be in (0, 10] s, false alarm in (0, 0.5), outlier k >= 3, gyro "
          "bias drift and temperature coefficient >= 0";
    }
    return false;
  }
  for (const BiasDrift& d : bias_drift) {
    std::string why;
    if (!d.IsValid(&why)) {
      if (error) *error = "stillness: the bias wander allowed for: " + why;
      return false;
    }
  }
  return true;
}

std::string StillFinding::Describe() const {
  const char axis_name = "xyz"[std::clamp(axis, 0, 2)];
  switch (kind) {
    case kNone:
      return "still";
    case kFilling:
      return "the stillness window is still filling";
    case kVariance:
      return fmt::format("{} {} scatter {:.3g} {} above the still limit {:.3g}", TriadName(triad),
                         axis_name, value, TriadUnit(triad), limit);
    case kDrift:
      return fmt::format("{} {} drifted {:.3g} {} within the window (still limit {:.3g})",
                         TriadName(triad), axis_name, value, TriadUnit(triad), limit);
    case kRate:
      return fmt::format("gyr {} reads {:.3g} rad/s beyond its bias (still limit {:.3g}): turning",
                         axis_name, value, limit);
  }
  return "?";
}

StillnessDetector::StillnessDetector(const NoiseProfile& profile, const StillnessOptions& options)
    : profile_(profile), options_(options) {
  // At least 8 samples; at most 100000 (10 s at 10 kHz), whatever a measured rate says.
  w_ = static_cast<int>(std::clamp(options.window_s * profile.rate_hz, 8.0, 100000.0));
  h_ = w_ / 2;
  ring_.resize(static_cast<std::size_t>(w_));
  scratch_.resize(static_cast<std::size_t>(w_));
  for (int t = 0; t < 3; ++t) use_[t] = profile.sigma[t].has_value();
  q_var_ = VarianceRatioLimit(options.false_alarm, w_ - 1, profile.sigma_dof);
  // A triad whose values correlate (NoiseProfile::lag_one): a window's variance has fewer
  // degrees of freedom, and its means (the halves', the gyro rate's) vary (1 + rho) / (1 - rho)
  // times more than independent values' would (never taken below 1: a negative correlation
  // only makes the tests a little stricter than they need be).
  double dof = profile.sigma_dof;
  for (int t = 0; t < 3; ++t) {
    const auto i = static_cast<std::size_t>(t);
    const double rho = profile.lag_one[i];
    dof_share_[i] = Ar1DofShare(rho);
    mean_inflation_[i] = std::max(1.0, Ar1MeanInflation(rho));
    q_var_base_[i] = VarianceRatioLimit(
        options.false_alarm, std::max(1.0, (w_ - 1) * dof_share_[i]), profile.TriadDof(t));
    if (use_[t]) dof = std::min(dof, profile.TriadDof(t));
  }
  q_var_triad_ = q_var_base_;
  fresh_.assign(static_cast<std::size_t>(w_), 0);
  z_ = TwoSidedZ(options.false_alarm, dof);
  // A stored profile carries what the calibrators identified before a restart.
  for (int t = 0; t < 3; ++t) {
    const auto& stored = profile_.identified_drift[static_cast<std::size_t>(t)];
    SetDriftScale(t, stored ? stored->scale : 1.0);
  }
  finding_.kind = StillFinding::kFilling;
}

double StillnessDetector::HalvesDriftLimit(int triad, int axis, double n1, double n2,
                                           double samples_per_value) const {
  const auto t = static_cast<std::size_t>(triad);
  if (!profile_.sigma[t] || !(n1 > 0) || !(n2 > 0)) return 0.0;
  const double sigma = (*profile_.sigma[t])[axis];
  const double scale = drift_scale_[t];
  const double wander = options_.bias_drift[t].HalvesDifferenceVariance(axis, n1 / profile_.rate_hz,
                                                                        n2 / profile_.rate_hz);
  const double held = std::max(1.0, samples_per_value) * mean_inflation_[t];
  return z_ * std::sqrt(sigma * sigma * held * (1 / n1 + 1 / n2) + scale * scale * wander);
}

void StillnessDetector::SetIdentifiedDrift(int triad, const IdentifiedDrift& identified) {
  profile_.identified_drift[static_cast<std::size_t>(triad)] = identified;
  SetDriftScale(triad, identified.scale);
}

void StillnessDetector::SetDriftScale(int triad, double scale) {
  const auto t = static_cast<std::size_t>(triad);
  drift_scale_[t] = std::isfinite(scale) && scale > 0 ? scale : 1.0;
  for (int a = 0; a < 3; ++a) {
    window_drift_limit_[3 * t + static_cast<std::size_t>(a)] =
        HalvesDriftLimit(triad, a, h_, w_ - h_, samples_per_value_[t]);
  }
}

const Eigen::Vector3d& StillnessDetector::At(std::size_t logical, int triad) const {
  return ring_[(head_ + logical) % ring_.size()].v[triad];
}

void StillnessDetector::Clear() {
  size_ = 0;
  head_ = 0;
  fresh_in_window_.fill(0);
  has_last_.fill(false);
  still_run_ = 0;
  medians_valid_ = false;
  finding_ = StillFinding{};
  finding_.kind = StillFinding::kFilling;
}

void StillnessDetector::Recompute() {
  for (int t = 0; t < 3; ++t) {
    if (!use_[t]) continue;
    for (int a = 0; a < 3; ++a) {
      const int c = 3 * t + a;
      anchor_[c] = size_ > 0 ? At(0, t)[a] : 0.0;
      s1_[c] = s2_[c] = h1_[c] = 0;
      for (std::size_t i = 0; i < size_; ++i) {
        const double d = At(i, t)[a] - anchor_[c];
        s1_[c] += d;
        s2_[c] += d * d;
        if (i < static_cast<std::size_t>(h_)) h1_[c] += d;
      }
    }
  }
  pushes_since_recompute_ = 0;
  UpdateHeld();
}

// A full window whose triad repeated at least a fifth of its samples held its values: the window's
// halves and its scatter average samples / values times fewer independent values, and the drift
// and variance limits are set for them (else a 50-Hz magnetometer in a 100-Hz stream breaks
// stillness on noise).
void StillnessDetector::UpdateHeld() {
  if (size_ < static_cast<std::size_t>(w_)) return;
  for (int t = 0; t < 3; ++t) {
    if (!use_[t]) continue;
    const auto i = static_cast<std::size_t>(t);
    const double k = HeldRepeats(w_, fresh_in_window_[i])
                         ? static_cast<double>(w_) / static_cast<double>(fresh_in_window_[i])
                         : 1.0;
    if (std::abs(k - samples_per_value_[i]) <= 0.02 * samples_per_value_[i]) continue;
    samples_per_value_[i] = k;
    const double values = std::max(2.0, static_cast<double>(w_) / k);
    q_var_triad_[i] = k > 1.0 ? VarianceRatioLimit(options_.false_alarm,
                                                   std::max(1.0, (values - 1) * dof_share_[i]),
                                                   profile_.TriadDof(t))
                              : q_var_base_[i];
    for (int a = 0; a < 3; ++a) {
      window_drift_limit_[3 * i + static_cast<std::size_t>(a)] =
          HalvesDriftLimit(t, a, h_, w_ - h_, k);
    }
  }
}

void StillnessDetector::UpdateMedians() {
  // At most kMedianSamples samples evenly spread over the window, the newest included: the
  // median's standard error is then 1.25 sigma / sqrt(128) = 0.11 sigma, and the threshold is
  // floored at the profile's noise, while a 1000 Hz stream no longer sorts 500 values per channel
  // 16 times a second (docs/PERFORMANCE.md, "Daemon under load").
  const std::size_t n = size_;
  const std::size_t stride = std::max<std::size_t>(1, (n + kMedianSamples - 1) / kMedianSamples);
  for (int t = 0; t < 3; ++t) {
    if (!use_[t]) continue;
    for (int a = 0; a < 3; ++a) {
      const int c = 3 * t + a;
      std::size_t m = 0;
      for (std::size_t i = n; i >= stride; i -= stride) scratch_[m++] = At(i - 1, t)[a];
      auto mid = scratch_.begin() + static_cast<long>(m / 2);
      std::nth_element(scratch_.begin(), mid, scratch_.begin() + static_cast<long>(m));
      const double med = *mid;
      for (std::size_t i = 0; i < m; ++i) scratch_[i] = std::abs(scratch_[i] - med);
      std::nth_element(scratch_.begin(), mid, scratch_.begin() + static_cast<long>(m));
      median_[c] = med;
      robust_sigma_[c] = std::max(kMadToSigma * *mid, (*profile_.sigma[t])[a]);
    }
  }
  medians_valid_ = true;
  pushes_since_median_ = 0;
}

bool StillnessDetector::IsOutlier(const StillSample& s) {
  if (size_ < static_cast<std::size_t>(w_)) return false;
  if (!medians_valid_ || pushes_since_median_ >= std::max(1, w_ / 4)) UpdateMedians();
  for (int t = 0; t < 3; ++t) {
    if (!use_[t] || !s.has(t)) continue;
    for (int a = 0; a < 3; ++a) {
      const int c = 3 * t + a;
      const double x = s.v[t][a];
      if (!std::isfinite(x) || std::abs(x - median_[c]) > options_.outlier_k * robust_sigma_[c]) {
        return true;
      }
    }
  }
  return false;
}

bool StillnessDetector::Push(const StillSample& s, StillSample* evicted, bool* has_evicted) {
  *has_evicted = false;
  if (std::isfinite(s.temp_c)) last_temp_c_ = s.temp_c;
  const auto w = static_cast<std::size_t>(w_);
  std::uint8_t fresh = 0;
  for (int t = 0; t < 3; ++t) {
    const auto i = static_cast<std::size_t>(t);
    if (!use_[t] || !s.has(t)) continue;
    if (!has_last_[i] || s.v[t] != last_value_[i]) fresh |= static_cast<std::uint8_t>(1u << t);
    last_value_[i] = s.v[t];
    has_last_[i] = true;
  }
  const std::size_t slot = size_ == w ? head_ : (head_ + size_) % w;
  if (size_ == w) {
    for (int t = 0; t < 3; ++t) {
      fresh_in_window_[static_cast<std::size_t>(t)] -= (fresh_[slot] >> t) & 1u;
    }
  }
  fresh_[slot] = fresh;
  for (int t = 0; t < 3; ++t) fresh_in_window_[static_cast<std::size_t>(t)] += (fresh >> t) & 1u;
  if (size_ == w) {
    *evicted = ring_[head_];
    *has_evicted = true;
    for (int t = 0; t < 3; ++t) {
      if (!use_[t]) continue;
      for (int a = 0; a < 3; ++a) {
        const int c = 3 * t + a;
        const double out = evicted->v[t][a] - anchor_[c];
        const double in = s.v[t][a] - anchor_[c];
        const double moves = At(static_cast<std::size_t>(h_), t)[a] - anchor_[c];
        s1_[c] += in - out;
        s2_[c] += in * in - out * out;
        h1_[c] += moves - out;
      }
    }
    ring_[head_] = s;
    head_ = (head_ + 1) % w;
  } else {
    ring_[(head_ + size_) % w] = s;
    ++size_;
    if (size_ == 1) {
      Recompute();
    } else {
      for (int t = 0; t < 3; ++t) {
        if (!use_[t]) continue;
        for (int a = 0; a < 3; ++a) {
          const int c = 3 * t + a;
          const double in = s.v[t][a] - anchor_[c];
          s1_[c] += in;
          s2_[c] += in * in;
          if (size_ <= static_cast<std::size_t>(h_)) h1_[c] += in;
        }
      }
    }
  }
  ++pushes_since_median_;
  if (++pushes_since_recompute_ >= w_) Recompute();
  if (size_ < w) {
    finding_ = StillFinding{};
    finding_.kind = StillFinding::kFilling;
    still_run_ = 0;
    return false;
  }
  Evaluate();
  if (finding_.kind == StillFinding::kNone) {
    ++still_run_;
    return true;
  }
  still_run_ = 0;
  return false;
}

void StillnessDetector::Evaluate() {
  const double n = w_, n1 = h_, n2 = w_ - h_;
  double worst = 1.0;
  StillFinding f;
  auto consider = [&](StillFinding::Kind kind, int t, int a, double value, double limit) {
    if (!std::isfinite(value)) {  // cannot vouch for stillness
      worst = std::numeric_limits<double>::infinity();
      f = StillFinding{kind, t, a, value, limit};
      return;
    }
    if (value > limit && value / limit > worst) {
      worst = value / limit;
      f = StillFinding{kind, t, a, value, limit};
    }
  };
  // The gyro bias's allowed move: the fixed allowance and its temperature's (once per evaluation).
  const double bias_allowance = options_.gyr_bias_drift_radps + TemperatureAllowance();
  for (int t = 0; t < 3; ++t) {
    if (!use_[t]) continue;
    for (int a = 0; a < 3; ++a) {
      const int c = 3 * t + a;
      const double sigma = (*profile_.sigma[t])[a];
      double var = (s2_[c] - s1_[c] * s1_[c] / n) / (n - 1);
      if (var < 0) var = 0;  // rounding; NaN stays NaN
      consider(StillFinding::kVariance, t, a, std::sqrt(var),
               sigma * std::sqrt(q_var_triad_[static_cast<std::size_t>(t)]));
      const double drift = (s1_[c] - h1_[c]) / n2 - h1_[c] / n1;
      consider(StillFinding::kDrift, t, a, std::abs(drift),
               window_drift_limit_[static_cast<std::size_t>(c)]);
      if (t == kTriadGyr) {
        const double mean = anchor_[c] + s1_[c] / n;
        const double limit =
            z_ * std::sqrt(sigma * sigma * mean_inflation_[kTriadGyr] / n +
                           profile_.gyr_bias_sigma_radps * profile_.gyr_bias_sigma_radps) +
            bias_allowance;
        consider(StillFinding::kRate, t, a, std::abs(mean - profile_.gyr_bias_radps[a]), limit);
      }
    }
  }
  finding_ = f;
}

void StillnessDetector::TrackGyroBias(const Eigen::Vector3d& mean_radps, double temp_c) {
  if (!mean_radps.allFinite()) return;
  profile_.gyr_bias_radps = mean_radps;
  profile_.gyr_bias_temp_c = temp_c;
}

double StillnessDetector::TemperatureAllowance() const {
  const double moved_c = std::abs(last_temp_c_ - profile_.gyr_bias_temp_c);
  if (!std::isfinite(moved_c)) return 0.0;
  return StillnessOptions::kTempcoSigmas * options_.gyr_bias_tempco_radps_per_c * moved_c;
}

std::string StillnessDetector::DescribeLimits() const {
  std::string out = fmt::format(
      "window {} samples ({:.2f} s); false alarm {:.0e} per test; variance ratio <= {:.3f}, "
      "drift <= {:.2f} sigma sqrt(4/W), gyro rate <= {:.2f} sigma + {:.3g} rad/s",
      w_, w_ / profile_.rate_hz, options_.false_alarm, q_var_, z_, z_,
      options_.gyr_bias_drift_radps);
  bool wander = false;
  for (const BiasDrift& d : options_.bias_drift) wander |= d.enabled();
  if (wander) out += " (the drift test allows for the bias wander too)";
  return out;
}

}  // namespace turncal
