// NoiseMeter (core/sequencing/stillness.h): the sensor's noise measured at start-up, with the
// stillness tests of the measurement itself.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/sequencing/stillness.h"
#include "core/sequencing/stillness_stats.h"
#include "core/sequencing/triad_accumulator.h"

namespace turncal {

using namespace stillness_stats;  // NOLINT(build/namespaces): the shared constants and quantiles

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
// The largest steady drift of a mean over one attempt, in sigmas of the noise, that is still
// (NoiseMeter::TriadNoise).
constexpr double kMaxDriftSigmas = 3.0;

bool Reason(std::string* why, const std::string& what) {
  *why = what;
  return false;
}

// What each of k part means takes from the squares (and the lag-one products) of n values with
// lag-one correlation rho: kappa = (1 + rho) / (1 - rho) values' share, taken at most n / (4 k),
// so that parts of a few values (a 25-Hz magnetometer's second) cannot run a correction away.
double CappedKappa(double rho, double n, double k) {
  return std::min(std::max(1.0, n / (4 * k)), Ar1MeanInflation(rho));
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

void NoiseMeter::Moments::Add(const Eigen::Vector3d& v) {
  if (n == 0) ref = v;
  const Eigen::Vector3d x = v - ref;
  if (n > 0) {
    lag += x.cwiseProduct(last);
    head += x;
    tail += last;
    ++pairs;
  }
  last = x;
  ++n;
  const Eigen::Vector3d d = v - mean;
  mean += d / static_cast<double>(n);
  m2 += d.cwiseProduct(v - mean);
}

Eigen::Vector3d NoiseMeter::Moments::LagOneSum() const {
  // sum (x_i - m)(x_{i-1} - m) = sum x_i x_{i-1} - m (sum x_i + sum x_{i-1}) + pairs m^2.
  const Eigen::Vector3d m = mean - ref;
  return lag - m.cwiseProduct(head + tail) + static_cast<double>(pairs) * m.cwiseProduct(m);
}

Eigen::Vector3d NoiseMeter::LagOne(int t) const {
  Eigen::Vector3d lag = Eigen::Vector3d::Zero(), m2 = Eigen::Vector3d::Zero();
  double n = 0;
  for (const auto& p : parts_) {
    const Moments& m = Of(p, t);
    lag += m.LagOneSum();
    m2 += m.m2;
    n += static_cast<double>(m.n);
  }
  // About the parts' own means, both sums lose about k kappa (kappa = (1 + rho) / (1 - rho)) of
  // the n values' share: the ratio is (n rho - k kappa) / (n - k kappa), solved here for rho
  // (a few fixed-point steps; +0.007 at rho 0.6 in 4 parts of 250), kappa capped (CappedKappa).
  // Within white noise's 2 / sqrt(n) the raw value is taken as chance (a 50-value second reads
  // +-0.14 on white noise): the noise is then white.
  const auto k = static_cast<double>(parts_.size());
  Eigen::Vector3d rho = Eigen::Vector3d::Zero();
  for (int a = 0; a < 3; ++a) {
    if (!(m2[a] > 0)) continue;
    const double raw = lag[a] / m2[a];
    if (!(std::abs(raw) > 2 / std::sqrt(n))) continue;
    double r = raw;
    for (int step = 0; step < 5; ++step) {
      const double kappa = CappedKappa(r, n, k);
      r = std::clamp((raw * (n - k * kappa) + k * kappa) / n, -0.99, 0.99);
    }
    rho[a] = r;
  }
  return rho;
}

Eigen::Vector3d NoiseMeter::Drift(int t) const {
  if (parts_.size() < 3) return Eigen::Vector3d::Zero();
  double sw = 0, sx = 0, sxx = 0;
  Eigen::Vector3d sy = Eigen::Vector3d::Zero(), sxy = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < parts_.size(); ++i) {
    const Moments& m = Of(parts_[i], t);
    const double w = static_cast<double>(m.n), x = static_cast<double>(i);
    sw += w;
    sx += w * x;
    sxx += w * x * x;
    sy += w * m.mean;
    sxy += w * x * m.mean;
  }
  const double det = sw * sxx - sx * sx;
  return det > 0 ? Eigen::Vector3d((sw * sxy - sx * sy) / det) : Eigen::Vector3d::Zero();
}

bool NoiseMeter::CountsHeldOnce(int t) const {
  std::int64_t samples = 0, values = 0;
  for (const auto& p : parts_) {
    if (p.fresh[static_cast<std::size_t>(t)].n < 3) return false;
    samples += p.all[static_cast<std::size_t>(t)].n;
    values += p.fresh[static_cast<std::size_t>(t)].n;
  }
  return HeldRepeats(samples, values);
}

const NoiseMeter::Moments& NoiseMeter::Of(const Part& p, int t) const {
  const auto i = static_cast<std::size_t>(t);
  return CountsHeldOnce(t) ? p.fresh[i] : p.all[i];
}

void NoiseMeter::Accumulate(std::uint8_t present, const std::vector<char>& keep,
                            std::int64_t* t_first_ns, std::int64_t* t_last_ns, std::int64_t* n) {
  std::array<std::optional<Eigen::Vector3d>, 3> previous;  // each triad's last value kept
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
      const auto ti = static_cast<std::size_t>(t);
      p.all[ti].Add(s.v[t]);
      if (!previous[ti] || *previous[ti] != s.v[t]) p.fresh[ti].Add(s.v[t]);
      previous[ti] = s.v[t];
    }
  }
}

bool NoiseMeter::TriadNoise(int t, NoiseProfile* profile, std::string* why) const {
  const int k = static_cast<int>(parts_.size());
  double nd = 0;
  Eigen::Vector3d pooled = Eigen::Vector3d::Zero(), grand = Eigen::Vector3d::Zero();
  for (const auto& p : parts_) {
    const Moments& m = Of(p, t);
    pooled += m.m2;
    grand += m.mean * static_cast<double>(m.n);
    nd += static_cast<double>(m.n);
  }
  const double dof = nd - k;
  grand /= nd;
  // The values' correlation (a filtering device): a part's variance then has (1 - rho^2) /
  // (1 + rho^2) of its values' degrees of freedom, and its mean (1 + rho) / (1 - rho) times the
  // variance of independent values' (first-order autoregressive noise); each part's mean takes
  // that many values' share of the squares, not one.
  const Eigen::Vector3d rho = LagOne(t);
  int worst = 0;
  for (int a = 1; a < 3; ++a) worst = std::abs(rho[a]) > std::abs(rho[worst]) ? a : worst;
  profile->lag_one[static_cast<std::size_t>(t)] = rho[worst];
  // A steady drift (Drift, per part) of at most kMaxDriftSigmas of the noise over the attempt (a
  // die's temperature: a fraction of a sigma per second; a hand or a table turning slowly moves
  // tens of them) is allowed; it spreads each part's values too, by drift^2 / 12 (the part one
  // unit of x long), taken out of the squares so that the noise is the sensor's. A larger one is
  // left in, and the means test below refuses it.
  Eigen::Vector3d drift = Drift(t), drift_sigmas = Eigen::Vector3d::Zero();
  std::array<bool, 3> on_line{};  // the axis's means tested against the line (else their mean)
  for (int a = 0; a < 3; ++a) {
    drift_sigmas[a] = std::abs(drift[a]) * k / std::sqrt(pooled[a] / std::max(1.0, nd - k));
    on_line[static_cast<std::size_t>(a)] = k >= 3 && drift_sigmas[a] <= kMaxDriftSigmas;
    if (!on_line[static_cast<std::size_t>(a)]) drift[a] = 0.0;
  }
  const Eigen::Vector3d drift_var = drift.cwiseAbs2() / 12.0;
  for (int a = 0; a < 3; ++a) {
    pooled[a] = std::max(0.0, pooled[a] - nd * drift_var[a]) /
                (nd - k * std::max(1.0, CappedKappa(rho[a], nd, k)));
  }
  Eigen::Vector3d sigma = pooled.cwiseSqrt();
  const double floor = kFloat32Resolution * std::max(grand.norm(), 1e-30);
  for (int a = 0; a < 3; ++a) sigma[a] = std::max(sigma[a], floor);
  // Stillness of the attempt: each part's variance against the pooled one (F test), and the
  // parts' means against a straight line through them (F test, k - 2 dof) when its drift is
  // within kMaxDriftSigmas, else (and with fewer than three parts) against their mean (k - 1): a
  // sensor whose bias drifts steadily -- a die warming or cooling in a climate chamber -- is
  // still, and the drift over one attempt does not change its noise. (Against their mean, such a
  // unit was refused second after second, 406 times in e2e_registry's chamber line under load.)
  double x_mean = 0;  // the parts' weighted mean position, where the line passes the grand mean
  for (std::size_t i = 0; i < parts_.size(); ++i) {
    x_mean += static_cast<double>(i) * static_cast<double>(Of(parts_[i], t).n) / nd;
  }
  for (int a = 0; a < 3; ++a) {
    const int means_dof = on_line[static_cast<std::size_t>(a)] ? k - 2 : k - 1;
    const double var = sigma[a] * sigma[a];
    const double dof_share = Ar1DofShare(rho[a]);
    // (Never below 1: a negative correlation only makes the test a little stricter than needed.)
    const double mean_inflation = std::max(1.0, Ar1MeanInflation(rho[a]));
    double means_chi2 = 0;
    for (std::size_t i = 0; i < parts_.size(); ++i) {
      const Moments& m = Of(parts_[i], t);
      const double n = static_cast<double>(m.n);
      const double pv = std::max(0.0, m.m2[a] - n * drift_var[a]) / (n - 1);
      const double hi =
          VarianceRatioLimit(options_.false_alarm / (2.0 * k * 9),
                             std::max(1.0, (n - 1) * dof_share), std::max(1.0, dof * dof_share));
      if (pv / var > hi) {
        return Reason(
            why,
            fmt::format(
                "not still while measuring the noise: {} {} variance of one part is {:.2f} times "
                "the pooled one (limit {:.2f})",
                TriadName(t), "xyz"[a], pv / var, hi));
      }
      // Against the line through the parts' means (Drift; it passes through their weighted
      // mean, the grand mean, at the weighted mean of x).
      const double d = m.mean[a] - grand[a] - drift[a] * (static_cast<double>(i) - x_mean);
      means_chi2 += d * d * n / (var * mean_inflation);
    }
    // The pooled variance is itself an estimate (50 values' worth for a 100-Hz magnetometer
    // whose values correlate): the sum is means_dof times an F variable, not a chi^2 (as a
    // chi^2, 3 of 1000 one-second attempts at such a magnetometer were refused, 0.01 were due).
    const double chi_lim = means_dof * VarianceRatioLimit(options_.false_alarm / 9.0, means_dof,
                                                          std::max(1.0, dof * dof_share));
    if (means_chi2 > chi_lim) {
      return Reason(
          why, fmt::format("not still while measuring the noise: the {} {} mean changed between "
                           "parts{} (chi^2 {:.1f} > {:.1f} on {} dof)",
                           TriadName(t), "xyz"[a],
                           k < 3 ? ""
                           : on_line[static_cast<std::size_t>(a)]
                               ? ", not along a steady drift"
                               : fmt::format(", by {:.1f} sigma in the attempt (a steady drift "
                                             "of at most {:.0f} is still)",
                                             drift_sigmas[a], kMaxDriftSigmas),
                           means_chi2, chi_lim, means_dof));
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
    // The mean of correlated values varies (1 + rho) / (1 - rho) times more.
    double inflation = 1.0;
    for (int a = 0; a < 3; ++a) inflation = std::max(inflation, Ar1MeanInflation(rho[a]));
    profile->gyr_bias_sigma_radps = sigma.maxCoeff() * std::sqrt(inflation / nd);
    double temp_sum = 0.0;
    int temp_n = 0;
    for (const StillSample& s : samples_) {
      if (std::isfinite(s.temp_c)) temp_sum += s.temp_c, ++temp_n;
    }
    if (temp_n > 0) profile->gyr_bias_temp_c = temp_sum / temp_n;
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
    if (!TriadNoise(t, &prof, &why)) return reject(why);
  }
  if (std::string why; !MeasureRate(&prof, &why)) return reject(why);
  prof.sigma_dof = dof;
  prof.measured_host_s =
      std::make_pair(static_cast<double>(t_first_ns) * 1e-9, static_cast<double>(t_last_ns) * 1e-9);
  prof.source =
      fmt::format("measured over {:.2f} s ({} samples, {} outliers left out)", span, n, outliers_);
  // Each triad's new values (its held repeats counted once).
  std::array<std::int64_t, 3> fresh{};
  for (const auto& p : parts_) {
    for (std::size_t t = 0; t < 3; ++t) fresh[t] += p.fresh[t].n;
  }
  for (int t = 0; t < 3; ++t) {
    const double rho = prof.lag_one[static_cast<std::size_t>(t)];
    // The values the triad's sigma came from (fewer than the samples when its held repeats are
    // counted once; TriadDof counts samples, as its users scale it).
    const double values =
        CountsHeldOnce(t) ? static_cast<double>(fresh[static_cast<std::size_t>(t)]) : nd;
    // Named when beyond white noise's 3 sigma (1 / sqrt(n)): a real correlation, not chance.
    if (!(present & (1u << t)) || std::abs(rho) <= 3.0 / std::sqrt(values)) continue;
    prof.source.insert(prof.source.size() - 1,
                       fmt::format("; the {}'s values correlate (lag one {:.2f}): {:.0f} effective "
                                   "degrees of freedom",
                                   TriadName(t), rho, prof.TriadDof(t) * values / nd));
  }
  for (int t = 0; t < 3; ++t) {
    if (!(present & (1u << t)) || !CountsHeldOnce(t)) continue;
    prof.source.insert(prof.source.size() - 1,
                       fmt::format("; the {}'s held repeats counted once: {} values", TriadName(t),
                                   fresh[static_cast<std::size_t>(t)]));
  }
  std::string error;
  if (!prof.IsValid(&error)) return reject(error);
  profile_ = prof;
  return Status::kMeasured;
}

}  // namespace turncal
