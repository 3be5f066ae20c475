// The IEEE 952 terms' fit (core/analysis/ieee_noise.h) against the simulator's truth
// (sim/noise_terms.h): the covariance model of the Allan variances against their scatter in
// simulated series, and the five terms of one simulated recording within 4 sigma of the truth.
// The coverage over 100 recordings is `turncal noise-montecarlo` (docs/ACCURACY.md).

#include "core/analysis/ieee_noise.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "core/analysis/allan.h"
#include "core/analysis/streaming_allan.h"
#include "sim/noise_terms.h"

namespace turncal {
namespace {

TEST(NoiseTerms, TheFlickerSumHasTheFlatAllanVarianceOfB) {
  const double b = 2e-5, dt = 0.01, span = 3600;
  const auto poles = sim::FlickerPoles(b, dt, span);
  for (double tau = 5 * dt; tau <= span / 3; tau *= 1.7) {
    double avar = 0;
    for (const auto& p : poles) avar += p.variance * GaussMarkovAvar(tau, p.tau_s);
    EXPECT_NEAR(avar / (b * b * IeeeUnitAvar(kIeeeB, tau)), 1.0, 0.015) << "tau " << tau;
  }
}

// The overlapping Allan variance at cluster size m of x, fully overlapping.
double Avar(const std::vector<double>& prefix, std::int64_t m) {
  const auto n = static_cast<std::int64_t>(prefix.size()) - 1;
  double sum = 0;
  std::int64_t terms = 0;
  for (std::int64_t k = 0; k + 2 * m <= n; ++k, ++terms) {
    const double d = prefix[static_cast<size_t>(k + 2 * m)] -
                     2 * prefix[static_cast<size_t>(k + m)] + prefix[static_cast<size_t>(k)];
    sum += d * d;
  }
  return sum / (2.0 * static_cast<double>(m * m) * static_cast<double>(terms));
}

struct CovarianceCase {
  const char* name;
  sim::NoiseTerms terms;
};

// Each random term with white rate beside it, and the ramp: the predicted variances of the
// Allan variances at m = 1, 4, 16, 64 and the correlation of neighbours against 1500 series of
// 2048 samples. The scatter of a variance estimated from 1500 series is 3.7 %: 18 % is 5 of it;
// a correlation's, about 0.03: 0.12.
TEST(IeeeNoise, TheCovarianceOfTheAllanVariancesIsTheirScatter) {
  const double dt = 0.01;
  const std::int64_t n = 2048;
  const std::vector<std::int64_t> ms = {1, 4, 16, 64};
  const CovarianceCase cases[] = {
      {"quantisation", {.q = 3e-4, .n = 1e-3}},
      {"flicker", {.n = 1e-3, .b = 5e-3}},  // white where the flicker sum is not flat
      {"random walk", {.n = 1e-3, .k = 2e-2}},
      {"ramp", {.n = 1e-3, .r = 2e-3}},
  };
  constexpr int kSeries = 1500;
  int seed = 1;
  for (const CovarianceCase& c : cases) {
    SCOPED_TRACE(c.name);
    std::vector<std::vector<double>> avars(ms.size());
    for (int s = 0; s < kSeries; ++s) {
      sim::NoiseTermsGenerator g(c.terms, dt, static_cast<double>(n) * dt, seed++);
      std::vector<double> prefix(static_cast<size_t>(n) + 1, 0.0);
      for (std::int64_t i = 0; i < n; ++i)
        prefix[static_cast<size_t>(i) + 1] = prefix[static_cast<size_t>(i)] + g.Next();
      for (std::size_t j = 0; j < ms.size(); ++j) avars[j].push_back(Avar(prefix, ms[j]));
    }
    const auto t = c.terms.AsArray();
    std::array<double, kIeeeTerms> theta{};
    for (int k = 0; k < kIeeeTerms; ++k)
      theta[static_cast<size_t>(k)] = t[static_cast<size_t>(k)] * t[static_cast<size_t>(k)];
    auto mean = [](const std::vector<double>& v) {
      double s = 0;
      for (double x : v) s += x;
      return s / static_cast<double>(v.size());
    };
    auto cov = [&](std::size_t a, std::size_t b) {
      const double ma = mean(avars[a]), mb = mean(avars[b]);
      double s = 0;
      for (int i = 0; i < kSeries; ++i)
        s += (avars[a][static_cast<size_t>(i)] - ma) * (avars[b][static_cast<size_t>(i)] - mb);
      return s / (kSeries - 1);
    };
    for (std::size_t j = 0; j < ms.size(); ++j) {
      const double predicted = AvarCovariance(ms[j], ms[j], dt, n, theta);
      EXPECT_NEAR(cov(j, j) / predicted, 1.0, 0.18) << "m " << ms[j];
      if (j + 1 < ms.size()) {
        const double predicted_rho =
            AvarCovariance(ms[j], ms[j + 1], dt, n, theta) /
            std::sqrt(predicted * AvarCovariance(ms[j + 1], ms[j + 1], dt, n, theta));
        const double rho = cov(j, j + 1) / std::sqrt(cov(j, j) * cov(j + 1, j + 1));
        EXPECT_NEAR(rho, predicted_rho, 0.12) << "m " << ms[j] << "," << ms[j + 1];
      }
    }
  }
}

// White rate alone against Howe, Allan and Barnes' closed form of the overlapping estimator's
// edf (NIST SP 1065 eq. 5.6): var = 2 avar^2 / edf, summed lag by lag at short cluster times and
// by Simpson's rule between the kinks at long ones.
TEST(IeeeNoise, TheWhiteRateVarianceIsTheClosedForms) {
  const double dt = 0.01;
  const std::int64_t n = 100000;
  const double big_n = static_cast<double>(n);
  for (std::int64_t m : {1, 10, 100, 1000, 10000}) {
    const double md = static_cast<double>(m);
    const double edf =
        (3 * (big_n - 1) / (2 * md) - 2 * (big_n - 2) / big_n) * 4 * md * md / (4 * md * md + 5);
    const double avar = 1.0 / (md * dt);  // N = 1
    const double v = AvarCovariance(m, m, dt, n, {0, 1, 0, 0, 0});
    EXPECT_NEAR(v / (2 * avar * avar / edf), 1.0, 0.03) << "m " << m;
  }
}

// A tactical gyroscope's axis at rest for four hours at 100 Hz, each term dominating a stretch of
// the curve (Q to N at 0.05 s, N to B at 5 s, B to K at 50 s, K to R at 400 s): every term
// resolved and within 4 sigma of its truth.
TEST(IeeeNoise, FindsTheFiveTermsOfASimulatedRecording) {
  const double dt = 0.01, hours = 4;
  const sim::NoiseTerms truth{.q = 1.3e-5, .n = 1e-4, .b = 6.7e-5, .k = 1.1e-5, .r = 4.5e-7};
  const auto n = static_cast<std::int64_t>(hours * 3600 / dt);
  sim::NoiseTermsGenerator g(truth, dt, static_cast<double>(n) * dt, 7);
  StreamingAllan allan(1);
  for (std::int64_t i = 0; i < n; ++i) {
    const double v = g.Next();
    allan.Add(&v);
  }
  std::vector<IeeeAvarPoint> points;
  for (const auto& p : allan.Points()) points.push_back({p.m, p.avar[0]});
  const IeeeNoiseFit fit = FitIeeeNoise(points, dt, n);
  ASSERT_TRUE(fit.ok) << fit.error;
  const auto t = truth.AsArray();
  for (int k = 0; k < kIeeeTerms; ++k) {
    const IeeeTermEstimate& e = fit.terms[static_cast<size_t>(k)];
    SCOPED_TRACE(IeeeTermName(k));
    // Four hours barely show the ramp (K gives way to it at 400 s, the longest cluster time is
    // 1600 s): it is within its sigma, not always 2 sigma from zero.
    if (k != kIeeeR) {
      EXPECT_TRUE(e.resolved) << e.value << " +- " << e.sigma;
    }
    EXPECT_NEAR(e.value, t[static_cast<size_t>(k)], 4 * e.sigma);
    EXPECT_LT(e.sigma, (k == kIeeeR ? 0.5 : 0.15) * t[static_cast<size_t>(k)]);
  }
  EXPECT_LT(fit.chi2, fit.dof + 5 * std::sqrt(2.0 * fit.dof)) << fit.points << " points";
}

}  // namespace
}  // namespace turncal
