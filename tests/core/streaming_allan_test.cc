// The streaming overlapping Allan and Hadamard variances (core/analysis/streaming_allan.h) and
// their degrees of freedom and intervals (core/analysis/allan_edf.h).
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "core/analysis/allan.h"
#include "core/analysis/allan_edf.h"
#include "core/analysis/streaming_allan.h"

namespace turncal {
namespace {

// The overlapping Hadamard variance at m, every starting point, from the series in memory.
double HadamardInMemory(const std::vector<double>& x, std::int64_t m) {
  std::vector<double> s(x.size() + 1, 0.0);
  for (std::size_t i = 0; i < x.size(); ++i) s[i + 1] = s[i] + (x[i] - x[0]);
  double sum = 0.0;
  std::int64_t terms = 0;
  for (std::int64_t k = 0; k + 3 * m < static_cast<std::int64_t>(s.size()); ++k, ++terms) {
    const double h = s[k + 3 * m] - 3 * s[k + 2 * m] + 3 * s[k + m] - s[k];
    sum += h * h;
  }
  return sum / (6.0 * static_cast<double>(m * m) * static_cast<double>(terms));
}

// White noise, a random-walking bias and gravity's offset; two channels (the second scaled).
std::vector<std::vector<double>> Series(std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal;
  std::vector<std::vector<double>> x(2, std::vector<double>(n));
  double walk = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    walk += 2e-3 * normal(rng);
    x[0][i] = 9.81 + walk + normal(rng);
    x[1][i] = -3.0 * x[0][i];
  }
  return x;
}

// Below 2R the streaming estimator is the fully overlapping one, to rounding; above it its
// starting points are m / R apart at most and it stays within a small fraction of the exact
// value (far inside the estimate's own scatter, 1 / sqrt(edf)).
TEST(StreamingAllan, MatchesTheOverlappingEstimatorInMemory) {
  const std::size_t n = 200000;
  const auto x = Series(n, 7);
  StreamingAllanOptions o;
  o.exact_clusters = 64;
  StreamingAllan allan(2, o);
  for (std::size_t i = 0; i < n; ++i) {
    const double v[2] = {x[0][i], x[1][i]};
    allan.Add(v);
  }
  EXPECT_EQ(allan.samples(), static_cast<std::int64_t>(n));
  const auto exact = OverlappingAllan(x[0], 1.0);
  const auto points = allan.Points();
  ASSERT_GT(points.size(), 40u);
  int compared = 0, strided = 0;
  for (const auto& p : points) {
    ASSERT_EQ(p.avar.size(), 2u);
    EXPECT_NEAR(p.avar[1], 9.0 * p.avar[0], 1e-9 * p.avar[1]) << "m " << p.m;
    EXPECT_EQ(p.avar_terms, 1 + (static_cast<std::int64_t>(n) - 2 * p.m) / p.stride) << p.m;
    const double rel = p.stride == 1 ? 1e-9 : 0.02;
    for (const auto& e : exact) {
      if (std::llround(e.tau_s) != p.m) continue;
      EXPECT_NEAR(p.avar[0], e.adev * e.adev, rel * p.avar[0]) << "m " << p.m;
      ++compared;
      strided += p.stride > 1;
    }
    if (!p.hvar.empty() && (p.m <= 300 || p.m % 997 == 0 || p.m == points.back().m)) {
      EXPECT_NEAR(p.hvar[0], HadamardInMemory(x[0], p.m), rel * 1.5 * p.hvar[0]) << "m " << p.m;
    }
  }
  EXPECT_GT(compared, 20);
  EXPECT_GT(strided, 3);
  EXPECT_EQ(points.front().m, 1);
  EXPECT_LE(2 * points.back().m, static_cast<std::int64_t>(n));
}

// Memory does not follow the recording: a million samples and eight million hold about the
// same (one more level per doubling of the longest cluster).
TEST(StreamingAllan, MemoryStaysFlat) {
  StreamingAllan allan(6);
  std::mt19937_64 rng(3);
  std::normal_distribution<double> normal;
  std::size_t at_1m = 0;
  double v[6];
  for (int i = 0; i < 8000000; ++i) {
    for (double& c : v) c = normal(rng);
    allan.Add(v);
    if (i + 1 == 1000000) at_1m = allan.MemoryBytes();
  }
  const std::size_t at_8m = allan.MemoryBytes();
  EXPECT_LT(at_8m, 8u << 20);
  EXPECT_LT(at_8m, at_1m + (at_1m / 2));  // 3 more levels on about 10
  // White noise: sigma^2(m) = 1 / m within its sampling error.
  for (const auto& p : allan.Points()) {
    const double edf = OverlappingEdf(0, 2, p.m, p.stride, allan.samples());
    for (double a : p.avar) EXPECT_NEAR(a * p.m, 1.0, 5.0 * std::sqrt(2.0 / edf)) << p.m;
  }
}

// The edf of white rate noise against the closed form of Howe, Allan and Barnes (1981) for the
// overlapping Allan variance, N phase points: (3(N-1)/(2m) - 2(N-2)/N) 4m^2 / (4m^2 + 5).
TEST(AllanEdf, WhiteRateNoiseMatchesTheClosedForm) {
  const std::int64_t n = 100000;
  for (std::int64_t m : {1, 2, 4, 16, 100, 1000, 10000}) {
    const double big_n = static_cast<double>(n + 1), mm = static_cast<double>(m);
    const double closed =
        (3 * (big_n - 1) / (2 * mm) - 2 * (big_n - 2) / big_n) * 4 * mm * mm / (4 * mm * mm + 5);
    EXPECT_NEAR(OverlappingEdf(0, 2, m, 1, n), closed, 0.05 * closed) << "m " << m;
  }
  EXPECT_EQ(OverlappingEdf(0, 2, 10, 1, 20), 0.0);  // no term
}

// The edf measured: many independent series, the estimate's relative variance 2 / edf. White
// rate (alpha 0), random-walk rate (-2) and white phase (2: the differences of white noise),
// Allan and Hadamard, fully overlapping and strided. 800 series: the measured edf's own
// sampling error is about 5 %.
TEST(AllanEdf, MatchesTheScatterOfTheEstimates) {
  const std::int64_t n = 2048;
  const int series = 800;
  StreamingAllanOptions o;
  o.exact_clusters = 16;  // clusters of 32 and more are strided
  for (int alpha : {0, -2, 2}) {
    std::mt19937_64 rng(100 + alpha);
    std::normal_distribution<double> normal;
    std::vector<std::vector<StreamingAllanPoint>> runs;
    for (int s = 0; s < series; ++s) {
      StreamingAllan allan(1, o);
      double walk = 0.0, previous = normal(rng);
      for (std::int64_t i = 0; i < n; ++i) {
        const double w = normal(rng);
        walk += w;
        double v = alpha == 0 ? w : alpha == -2 ? walk : w - previous;
        previous = w;
        allan.Add(&v);
      }
      runs.push_back(allan.Points());
    }
    for (std::size_t i = 0; i < runs[0].size(); ++i) {
      const auto& p = runs[0][i];
      if (p.m != 4 && p.m != 20 && p.m != 64 && p.m != 160) continue;
      for (int d : {2, 3}) {
        double mean = 0, m2 = 0;
        int count = 0;
        for (const auto& r : runs) {
          const auto& v = d == 2 ? r[i].avar : r[i].hvar;
          if (v.empty()) continue;
          mean += v[0], m2 += v[0] * v[0], ++count;
        }
        if (count < series) continue;
        mean /= count;
        const double var = m2 / count - mean * mean;
        const double measured = 2 * mean * mean / var;
        const double predicted = OverlappingEdf(alpha, d, p.m, p.stride, n);
        EXPECT_NEAR(measured / predicted, 1.0, 0.2)
            << "alpha " << alpha << " d " << d << " m " << p.m << " stride " << p.stride
            << ": measured edf " << measured << ", predicted " << predicted;
      }
    }
  }
}

TEST(AllanEdf, IntervalsAndNoiseTypes) {
  const VarianceInterval v = ChiSquaredInterval(1.0, 100.0, 0.95);
  EXPECT_NEAR(v.low, 100.0 / 129.561, 1e-3);
  EXPECT_NEAR(v.high, 100.0 / 74.2219, 1e-3);
  EXPECT_EQ(NoiseTypeOfSlope(-2.0), 2);
  EXPECT_EQ(NoiseTypeOfSlope(-1.0), 0);
  EXPECT_EQ(NoiseTypeOfSlope(0.05), -1);
  EXPECT_EQ(NoiseTypeOfSlope(1.0), -2);
  EXPECT_EQ(NoiseTypeOfSlope(2.0), -2);
  EXPECT_EQ(NoiseTypeOfSlope(-3.0), 2);
}

}  // namespace
}  // namespace turncal
