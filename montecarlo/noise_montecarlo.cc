#include "montecarlo/noise_montecarlo.h"

#include <chrono>
#include <cmath>

#include "core/analysis/streaming_allan.h"
#include "montecarlo/parallel_runs.h"
#include "montecarlo/z_scores.h"

namespace turncal::montecarlo {

bool NoiseMonteCarloSummary::Passed() const {
  if (runs.empty()) return false;
  for (const NoiseTermSummary& t : terms) {
    if (100 * t.covered < 93 * static_cast<int>(runs.size())) return false;
  }
  return true;
}

namespace {

// Per term: coverage and z-scores of one of a run's fits.
std::array<NoiseTermSummary, kIeeeTerms> Summarise(const std::vector<NoiseRun>& runs,
                                                   const std::array<double, kIeeeTerms>& truth,
                                                   IeeeNoiseFit NoiseRun::*which) {
  std::array<NoiseTermSummary, kIeeeTerms> terms;
  std::vector<ZScoreSummary> z(kIeeeTerms, ZScoreSummary(1));
  for (const NoiseRun& r : runs) {
    const IeeeNoiseFit& fit = r.*which;
    if (!fit.ok) continue;
    for (int k = 0; k < kIeeeTerms; ++k) {
      const IeeeTermEstimate& e = fit.terms[static_cast<size_t>(k)];
      NoiseTermSummary& t = terms[static_cast<size_t>(k)];
      const double truth_k = truth[static_cast<size_t>(k)];
      ++t.fitted;
      t.covered += truth_k >= e.low95 && truth_k <= e.high95;
      t.resolved += e.resolved;
      t.mean_value += e.value;
      t.mean_sigma += e.sigma;
      // A term fitted at zero has no sigma and no z.
      if (e.sigma > 0)
        z[static_cast<size_t>(k)].Add(Eigen::VectorXd::Constant(1, (e.value - truth_k) / e.sigma));
    }
  }
  for (int k = 0; k < kIeeeTerms; ++k) {
    NoiseTermSummary& t = terms[static_cast<size_t>(k)];
    if (t.fitted > 0) t.mean_value /= t.fitted, t.mean_sigma /= t.fitted;
    const ZScoreSummary& zk = z[static_cast<size_t>(k)];
    if (zk.runs() == 0) continue;
    t.mean_z = zk.Mean()[0];
    t.std_z = zk.Std()[0];
  }
  return terms;
}

}  // namespace

NoiseMonteCarloSummary RunNoiseMonteCarlo(const NoiseMonteCarloOptions& options) {
  NoiseMonteCarloSummary s;
  const double dt = 1.0 / options.rate_hz;
  const auto n = static_cast<std::int64_t>(std::llround(options.hours * 3600.0 * options.rate_hz));
  s.samples_per_run = n;
  std::atomic<int> done{0};
  s.runs = RunInParallel<NoiseRun>(options.runs, options.jobs, [&](int i, NoiseRun* out) {
    const auto start = std::chrono::steady_clock::now();
    sim::NoiseTermsGenerator generator(options.truth, dt, static_cast<double>(n) * dt,
                                       options.seed + static_cast<std::uint64_t>(i));
    StreamingAllan allan(1);
    for (std::int64_t k = 0; k < n; ++k) {
      const double v = generator.Next();
      allan.Add(&v);
    }
    std::vector<IeeeAvarPoint> points;
    for (const StreamingAllanPoint& p : allan.Points()) points.push_back({p.m, p.avar[0]});
    const auto fit_start = std::chrono::steady_clock::now();
    out->fit = FitIeeeNoise(points, dt, n);
    out->independent = FitIeeeNoise(points, dt, n, /*independent=*/true);
    const auto end = std::chrono::steady_clock::now();
    out->seconds = std::chrono::duration<double>(end - start).count();
    out->fit_seconds = std::chrono::duration<double>(end - fit_start).count();
    const int d = ++done;
    if (options.on_run) options.on_run(d);
  });
  const std::array<double, kIeeeTerms> truth = options.truth.AsArray();
  int fitted = 0;
  for (const NoiseRun& r : s.runs) {
    if (!r.fit.ok) {
      ++s.failed;
      continue;
    }
    ++fitted;
    s.mean_fit_points += r.fit.points;
  }
  if (fitted > 0) s.mean_fit_points /= fitted;
  s.terms = Summarise(s.runs, truth, &NoiseRun::fit);
  s.independent = Summarise(s.runs, truth, &NoiseRun::independent);
  return s;
}

}  // namespace turncal::montecarlo
