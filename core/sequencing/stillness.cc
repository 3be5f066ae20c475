#include "core/sequencing/stillness.h"

#include <fmt/format.h>

#include <algorithm>
#include <boost/math/distributions/chi_squared.hpp>
#include <boost/math/distributions/fisher_f.hpp>
#include <boost/math/distributions/normal.hpp>
#include <boost/math/distributions/students_t.hpp>
#include <cmath>

namespace turncal {
namespace {

constexpr double kMadToSigma = 1.4826;  // sigma / MAD of a normal distribution
// A measured sigma below the float32 resolution of the value is the sensor's quantisation, not
// its noise; the floor keeps limits finite for a sensor that repeats the same value.
constexpr double kFloat32Resolution = 1.2e-7;
// One start-up attempt keeps at most this many samples (60 s at 10 kHz).
constexpr std::size_t kMaxMeterSamples = 600000;

// Two-sided normal (or Student's t with `dof`) quantile for a tail probability `alpha`.
double TwoSidedZ(double alpha, double dof) {
  if (std::isfinite(dof)) {
    return boost::math::quantile(boost::math::complement(boost::math::students_t(dof), alpha / 2));
  }
  return boost::math::quantile(boost::math::complement(boost::math::normal(), alpha / 2));
}

// Upper quantile of s^2 / sigma^2 for a variance from `n_dof` dof when sigma^2 came from `dof`.
double VarianceRatioLimit(double alpha, double n_dof, double dof) {
  if (std::isfinite(dof)) {
    return boost::math::quantile(boost::math::complement(boost::math::fisher_f(n_dof, dof), alpha));
  }
  return boost::math::quantile(boost::math::complement(boost::math::chi_squared(n_dof), alpha)) /
         n_dof;
}

}  // namespace

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

bool NoiseMeterOptions::IsValid(std::string* error) const {
  if (!(duration_s > 0) || duration_s > 60 || sub_windows < 2 ||
      !(false_alarm > 0 && false_alarm < 1) || !(gyr_bias_limit_radps > 0) || !(outlier_k >= 3) ||
      !(max_outlier_fraction >= 0 && max_outlier_fraction < 0.5)) {
    if (error) {
      *error =
          "noise measurement: duration in (0, 60] s, at least 2 parts, false alarm in (0, 1), "
          "outlier k >= 3, outlier fraction in [0, 0.5)";
    }
    return false;
  }
  return true;
}

NoiseMeter::NoiseMeter(const NoiseMeterOptions& options) : options_(options) { Restart(); }

void NoiseMeter::Restart() {
  samples_.clear();
  outliers_ = 0;
  parts_.assign(static_cast<std::size_t>(options_.sub_windows), Part{});
  failure_.clear();
}

NoiseMeter::Status NoiseMeter::Add(const StillSample& s) {
  if (!samples_.empty() && (static_cast<double>(s.t_host_ns - samples_.front().t_host_ns) * 1e-9 >=
                                options_.duration_s ||
                            samples_.size() >= kMaxMeterSamples)) {
    return Finish();
  }
  samples_.push_back(s);
  return Status::kCollecting;
}

namespace {
bool Reason(std::string* why, const std::string& what) {
  *why = what;
  return false;
}
}  // namespace

std::uint8_t NoiseMeter::PresentTriads() const {
  std::uint8_t present = 0;
  for (int t = 0; t < 3; ++t) {
    std::size_t with = 0;
    for (const auto& s : samples_) with += s.has(t) ? 1 : 0;
    if (2 * with > samples_.size()) present |= static_cast<std::uint8_t>(1u << t);
  }
  return present;
}

std::vector<char> NoiseMeter::KeptSamples(std::uint8_t present) const {
  std::vector<char> keep(samples_.size(), 1);
  for (std::size_t i = 0; i < samples_.size(); ++i) {
    if ((samples_[i].present & present) != present) keep[i] = 0;
  }
  // Isolated outliers: beyond outlier_k robust sigmas (1.4826 MAD) of the attempt's median.
  std::vector<double> values;
  values.reserve(samples_.size());
  for (int t = 0; t < 3; ++t) {
    if (!(present & (1u << t))) continue;
    for (int a = 0; a < 3; ++a) {
      values.clear();
      for (std::size_t i = 0; i < samples_.size(); ++i) {
        if (samples_[i].has(t)) values.push_back(samples_[i].v[t][a]);
      }
      auto mid = values.begin() + static_cast<long>(values.size() / 2);
      std::nth_element(values.begin(), mid, values.end());
      const double med = *mid;
      for (auto& v : values) v = std::abs(v - med);
      std::nth_element(values.begin(), mid, values.end());
      const double robust = std::max(kMadToSigma * *mid, kFloat32Resolution * std::abs(med));
      for (std::size_t i = 0; i < samples_.size(); ++i) {
        if (!keep[i]) continue;
        const double x = samples_[i].v[t][a];
        if (!std::isfinite(x) || std::abs(x - med) > options_.outlier_k * robust) keep[i] = 0;
      }
    }
  }
  return keep;
}

void NoiseMeter::Accumulate(std::uint8_t present, const std::vector<char>& keep,
                            std::int64_t* t_first_ns, std::int64_t* t_last_ns, std::int64_t* n) {
  for (std::size_t i = 0; i < samples_.size(); ++i) {
    const StillSample& s = samples_[i];
    if (!keep[i]) {
      ++outliers_;
      continue;
    }
    if (*n == 0) *t_first_ns = s.t_host_ns;
    *t_last_ns = s.t_host_ns;
    ++*n;
    const double since = static_cast<double>(s.t_host_ns - samples_.front().t_host_ns) * 1e-9;
    const auto k = std::min<std::size_t>(
        parts_.size() - 1,
        static_cast<std::size_t>(std::max(0.0, since / options_.duration_s) * parts_.size()));
    Part& p = parts_[k];
    ++p.n;
    for (int t = 0; t < 3; ++t) {
      if (!(present & (1u << t))) continue;
      const Eigen::Vector3d d = s.v[t] - p.mean[t];
      p.mean[t] += d / static_cast<double>(p.n);
      p.m2[t] += d.cwiseProduct(s.v[t] - p.mean[t]);
    }
  }
}

bool NoiseMeter::TriadNoise(int t, double nd, NoiseProfile* profile, std::string* why) const {
  const int k = static_cast<int>(parts_.size());
  const double dof = nd - k;
  Eigen::Vector3d pooled = Eigen::Vector3d::Zero(), grand = Eigen::Vector3d::Zero();
  for (const auto& p : parts_) {
    pooled += p.m2[t];
    grand += p.mean[t] * static_cast<double>(p.n);
  }
  pooled /= dof;
  grand /= nd;
  Eigen::Vector3d sigma = pooled.cwiseSqrt();
  const double floor = kFloat32Resolution * std::max(grand.norm(), 1e-30);
  for (int a = 0; a < 3; ++a) sigma[a] = std::max(sigma[a], floor);
  // Stillness of the attempt: each part's variance against the pooled one (F test), and the
  // parts' means against each other (chi^2 with k - 1 dof).
  for (int a = 0; a < 3; ++a) {
    const double var = sigma[a] * sigma[a];
    double means_chi2 = 0;
    for (const auto& p : parts_) {
      const double pv = p.m2[t][a] / static_cast<double>(p.n - 1);
      const double hi = VarianceRatioLimit(options_.false_alarm / (2.0 * k * 9),
                                           static_cast<double>(p.n - 1), dof);
      if (pv / var > hi) {
        return Reason(
            why,
            fmt::format(
                "not still while measuring the noise: {} {} variance of one part is {:.2f} times "
                "the pooled one (limit {:.2f})",
                TriadName(t), "xyz"[a], pv / var, hi));
      }
      const double d = p.mean[t][a] - grand[a];
      means_chi2 += d * d * static_cast<double>(p.n) / var;
    }
    const double chi_lim = boost::math::quantile(
        boost::math::complement(boost::math::chi_squared(k - 1), options_.false_alarm / 9.0));
    if (means_chi2 > chi_lim) {
      return Reason(
          why,
          fmt::format("not still while measuring the noise: the {} {} mean changed between parts "
                      "(chi^2 {:.1f} > {:.1f} on {} dof)",
                      TriadName(t), "xyz"[a], means_chi2, chi_lim, k - 1));
    }
  }
  profile->sigma[t] = sigma;
  if (t == kTriadGyr) {
    profile->gyr_bias_radps = grand;
    if (grand.norm() > options_.gyr_bias_limit_radps) {
      return Reason(
          why,
          fmt::format(
              "not still while measuring the noise: the gyro reads {:.3g} rad/s ({:.2f} deg/s), "
              "more than a bias ({:.3g} rad/s allowed)",
              grand.norm(), grand.norm() * 180 / M_PI, options_.gyr_bias_limit_radps));
    }
    profile->gyr_bias_sigma_radps = sigma.maxCoeff() / std::sqrt(nd);
  }
  return true;
}

bool NoiseMeter::MeasureRate(NoiseProfile* profile, std::string* why) const {
  const auto total = static_cast<double>(samples_.size());
  // The rate over every sample of the attempt (outliers were received too); host receive times
  // come in bursts, and a device clock need not keep the host's pace (the simulator's at
  // --live-speed 10), so the device clock's median spacing is preferred when most samples have
  // it: robust to lost samples, which only lengthen a few spacings, and to the odd sample
  // without a time stamp, a frame whose time field a bit error took out under a weak checksum.
  // (Requiring every sample's stamp, one such frame in the attempt timed the whole session by
  // host receive times: at 10x a 3 s dwell became 30 device seconds, 6 times the table's hold,
  // whose replayed samples then counted 3 times over in every record; faults_ber-1e-3.)
  const double span_all =
      static_cast<double>(samples_.back().t_host_ns - samples_.front().t_host_ns) * 1e-9;
  if (!(span_all > 0))
    return Reason(why, "the samples of the noise measurement share one timestamp");
  profile->rate_hz = (total - 1) / span_all;
  std::vector<double> spacing;
  std::size_t timed = samples_.front().t_device_s ? 1 : 0;
  for (std::size_t i = 1; i < samples_.size(); ++i) {
    if (samples_[i].t_device_s) ++timed;
    if (samples_[i].t_device_s && samples_[i - 1].t_device_s) {
      spacing.push_back(*samples_[i].t_device_s - *samples_[i - 1].t_device_s);
    }
  }
  if (2 * timed > samples_.size() && !spacing.empty()) {
    auto mid = spacing.begin() + static_cast<long>(spacing.size() / 2);
    std::nth_element(spacing.begin(), mid, spacing.end());
    if (*mid > 0) {
      profile->device_period_s = *mid;
      profile->rate_hz = 1.0 / *mid;
    }
  }
  return true;
}

NoiseMeter::Status NoiseMeter::Finish() {
  auto reject = [&](const std::string& why) {
    failure_ = why;
    return Status::kRejected;
  };
  // The triads the device sends: those in most samples. A sample without one of them (a frame
  // that passed its checksum corrupted, e.g. an Xbus item id flipped under the 8-bit checksum)
  // is left out below, instead of taking the triad out of the session's profile.
  std::uint8_t present = PresentTriads();
  if (!options_.use_mag) present &= static_cast<std::uint8_t>(~(1u << kTriadMag));
  // A magnetometer alone (a compass module, MIP 0x80/0x06 only) is still when its field is: it
  // cannot see a turn about the field's direction, which leaves its reading as it was anyway.
  if (!(present & (1u << kTriadAcc)) && !(present & (1u << kTriadGyr)) &&
      !(present & (1u << kTriadMag))) {
    return reject(options_.use_mag ? "the samples carry no triad"
                                   : "the samples carry neither accelerometer nor gyro");
  }
  const std::vector<char> keep = KeptSamples(present);
  std::int64_t t_first_ns = 0, t_last_ns = 0, n = 0;
  Accumulate(present, keep, &t_first_ns, &t_last_ns, &n);
  const auto total = static_cast<double>(samples_.size());
  if (static_cast<double>(outliers_) > options_.max_outlier_fraction * total) {
    return reject(
        fmt::format("not still while measuring the noise: {} of {} samples far from the median",
                    outliers_, samples_.size()));
  }
  const double span = static_cast<double>(t_last_ns - t_first_ns) * 1e-9;
  const int k = static_cast<int>(parts_.size());
  for (const auto& p : parts_) {
    if (p.n < 3) {
      return reject(fmt::format(
          "too few samples to measure the noise ({} in {:.2f} s, a part had {})", n, span, p.n));
    }
  }
  NoiseProfile prof;
  const auto nd = static_cast<double>(n);
  const double dof = nd - k;
  for (int t = 0; t < 3; ++t) {
    if (!(present & (1u << t))) continue;
    std::string why;
    if (!TriadNoise(t, nd, &prof, &why)) return reject(why);
  }
  if (std::string why; !MeasureRate(&prof, &why)) return reject(why);
  prof.sigma_dof = dof;
  prof.source =
      fmt::format("measured over {:.2f} s ({} samples, {} outliers left out)", span, n, outliers_);
  std::string error;
  if (!prof.IsValid(&error)) return reject(error);
  profile_ = prof;
  return Status::kMeasured;
}

bool StillnessOptions::IsValid(std::string* error) const {
  if (!(window_s > 0 && window_s <= 10) || !(false_alarm > 0 && false_alarm < 0.5) ||
      !(outlier_k >= 3) || !(gyr_bias_drift_radps >= 0)) {
    if (error) {
      *error =
          "stillness: window must be in (0, 10] s, false alarm in (0, 0.5), outlier k >= 3, gyro "
          "bias drift >= 0";
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
  const double dof = profile.sigma_dof;
  q_var_ = VarianceRatioLimit(options.false_alarm, w_ - 1, dof);
  z_ = TwoSidedZ(options.false_alarm, dof);
  // A stored profile carries what the calibrators identified before a restart.
  for (int t = 0; t < 3; ++t) {
    const auto& stored = profile_.identified_drift[static_cast<std::size_t>(t)];
    SetDriftScale(t, stored ? stored->scale : 1.0);
  }
  finding_.kind = StillFinding::kFilling;
}

double StillnessDetector::HalvesDriftLimit(int triad, int axis, double n1, double n2) const {
  const auto t = static_cast<std::size_t>(triad);
  if (!profile_.sigma[t] || !(n1 > 0) || !(n2 > 0)) return 0.0;
  const double sigma = (*profile_.sigma[t])[axis];
  const double scale = drift_scale_[t];
  const double wander = options_.bias_drift[t].HalvesDifferenceVariance(axis, n1 / profile_.rate_hz,
                                                                        n2 / profile_.rate_hz);
  return z_ * std::sqrt(sigma * sigma * (1 / n1 + 1 / n2) + scale * scale * wander);
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
        HalvesDriftLimit(triad, a, h_, w_ - h_);
  }
}

const Eigen::Vector3d& StillnessDetector::At(std::size_t logical, int triad) const {
  return ring_[(head_ + logical) % ring_.size()].v[triad];
}

void StillnessDetector::Clear() {
  size_ = 0;
  head_ = 0;
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
  const auto w = static_cast<std::size_t>(w_);
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
  for (int t = 0; t < 3; ++t) {
    if (!use_[t]) continue;
    for (int a = 0; a < 3; ++a) {
      const int c = 3 * t + a;
      const double sigma = (*profile_.sigma[t])[a];
      double var = (s2_[c] - s1_[c] * s1_[c] / n) / (n - 1);
      if (var < 0) var = 0;  // rounding; NaN stays NaN
      consider(StillFinding::kVariance, t, a, std::sqrt(var), sigma * std::sqrt(q_var_));
      const double drift = (s1_[c] - h1_[c]) / n2 - h1_[c] / n1;
      consider(StillFinding::kDrift, t, a, std::abs(drift),
               window_drift_limit_[static_cast<std::size_t>(c)]);
      if (t == kTriadGyr) {
        const double mean = anchor_[c] + s1_[c] / n;
        const double limit = z_ * std::sqrt(sigma * sigma / n + profile_.gyr_bias_sigma_radps *
                                                                    profile_.gyr_bias_sigma_radps) +
                             options_.gyr_bias_drift_radps;
        consider(StillFinding::kRate, t, a, std::abs(mean - profile_.gyr_bias_radps[a]), limit);
      }
    }
  }
  finding_ = f;
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
