#pragma once
// The IEEE 952 terms' Monte Carlo (issue 39 item 5): recordings of one axis at rest drawn with
// known Q, N, B, K, R (sim/noise_terms.h), each through the streaming Allan variance and the
// terms' fit (core/analysis/ieee_noise.h) as `turncal noise` runs them; per term, how often the
// stated 95 % interval holds the truth and the z-scores (value - truth) / sigma.

#include <array>
#include <cstdint>
#include <functional>
#include <vector>

#include "core/analysis/ieee_noise.h"
#include "sim/noise_terms.h"

namespace turncal::montecarlo {

struct NoiseMonteCarloOptions {
  // A tactical gyroscope's axis, rad/s: Q gives way to N at 0.05 s, N to B at 5 s, B to K at
  // 50 s, K to R at 400 s.
  sim::NoiseTerms truth{.q = 1.3e-5, .n = 1e-4, .b = 6.7e-5, .k = 1.1e-5, .r = 4.5e-7};
  double rate_hz = 100.0;
  double hours = 4.0;
  int runs = 100;
  std::uint64_t seed = 1;
  int jobs = 2;
  std::function<void(int done)> on_run;  // after each run, from the thread that ran it
};

struct NoiseRun {
  IeeeNoiseFit fit;
  IeeeNoiseFit independent;  // the same points fitted as if uncorrelated, for comparison
  double seconds = 0.0;      // to draw, sum and fit
  double fit_seconds = 0.0;  // of which to fit
};

struct NoiseTermSummary {
  int fitted = 0;    // runs with a fit
  int covered = 0;   // truth within [low95, high95]
  int resolved = 0;  // runs where the term is 2 sigma from zero
  // Over the runs where the term is non-zero (ZScoreSummary: the spread is the population one).
  double mean_z = 0.0, std_z = 0.0;
  double mean_value = 0.0, mean_sigma = 0.0;
};

struct NoiseMonteCarloSummary {
  std::vector<NoiseRun> runs;
  std::array<NoiseTermSummary, kIeeeTerms> terms;
  std::array<NoiseTermSummary, kIeeeTerms> independent;  // the plain weighted fit's
  std::int64_t samples_per_run = 0;
  double mean_fit_points = 0.0;
  int failed = 0;
  // Every term's truth within its 95 % interval in at least 93 % of the runs.
  bool Passed() const;
};

NoiseMonteCarloSummary RunNoiseMonteCarlo(const NoiseMonteCarloOptions& options);

}  // namespace turncal::montecarlo
