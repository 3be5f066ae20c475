#include "tools/noise_montecarlo_command.h"

#include <fmt/format.h>

#include <memory>
#include <nlohmann/json.hpp>

#include "montecarlo/noise_montecarlo.h"
#include "tools/help_text.h"

namespace turncal::tools {
namespace {

struct NoiseMonteCarloArgs {
  montecarlo::NoiseMonteCarloOptions engine;
  bool json = false;
};

constexpr Manual kNoiseMonteCarloManual = {
    "Draws rests of one axis with known IEEE 952 noise terms (quantisation Q, random walk N, "
    "bias instability B as flicker, rate random walk K, rate ramp R; sim/noise_terms.h), runs "
    "each through the streaming Allan variance and the terms' generalised least squares as "
    "`turncal noise` does, and counts per term how often the stated 95 % interval holds the "
    "truth, with the z-scores (value - truth) / sigma. The default truth is a tactical "
    "gyroscope's axis in rad/s, each term dominating a stretch of the curve.",
    "turncal noise-montecarlo --runs 100\n"
    "turncal noise-montecarlo --runs 100 --hours 10 --rate 400 --jobs 2\n"
    "turncal noise-montecarlo --runs 50 --R 0 --json   # no ramp: R's upper bound",
    "0 every term's interval held the truth in at least 93 % of the runs; 1 otherwise; 2 a "
    "command-line mistake",
    "docs/ACCURACY.md (\"Noise terms\"), docs/NOISE.md"};

void PrintText(const montecarlo::NoiseMonteCarloOptions& o,
               const montecarlo::NoiseMonteCarloSummary& s) {
  const auto truth = o.truth.AsArray();
  double seconds = 0, fit_seconds = 0;
  for (const auto& r : s.runs) seconds += r.seconds, fit_seconds += r.fit_seconds;
  const double runs = std::max<double>(1.0, static_cast<double>(s.runs.size()));
  fmt::print(
      "{} runs of {:.1f} h at {:g} Hz ({} samples each; {:.2f} s a run to draw, sum and fit, "
      "{:.3f} s of it to fit; {:.1f} Allan variances fitted on average; {} failed)\n",
      s.runs.size(), o.hours, o.rate_hz, s.samples_per_run, seconds / runs, fit_seconds / runs,
      s.mean_fit_points, s.failed);
  fmt::print("{:<4} {:>11} {:>11} {:>11} {:>10} {:>8} {:>7} {:>9}\n", "term", "truth", "mean value",
             "mean sigma", "95% holds", "mean z", "std z", "resolved");
  for (int k = 0; k < kIeeeTerms; ++k) {
    const auto& t = s.terms[static_cast<size_t>(k)];
    fmt::print("{:<4} {:>11.4g} {:>11.4g} {:>11.3g} {:>6}/{:<3} {:>8.3f} {:>7.3f} {:>9}\n",
               IeeeTermName(k), truth[static_cast<size_t>(k)], t.mean_value, t.mean_sigma,
               t.covered, t.fitted, t.mean_z, t.std_z, t.resolved);
  }
  fmt::print(
      "The same Allan variances fitted as if independent (each its own scatter, as a plain "
      "weighted fit does):\n");
  for (int k = 0; k < kIeeeTerms; ++k) {
    const auto& t = s.independent[static_cast<size_t>(k)];
    fmt::print("{:<4} {:>11.4g} {:>11.4g} {:>11.3g} {:>6}/{:<3} {:>8.3f} {:>7.3f} {:>9}\n",
               IeeeTermName(k), truth[static_cast<size_t>(k)], t.mean_value, t.mean_sigma,
               t.covered, t.fitted, t.mean_z, t.std_z, t.resolved);
  }
  fmt::print("{}\n", s.Passed() ? "every term's 95 % interval held the truth in >= 93 % of the runs"
                                : "a term's 95 % interval held the truth in < 93 % of the runs");
}

void PrintJson(const montecarlo::NoiseMonteCarloOptions& o,
               const montecarlo::NoiseMonteCarloSummary& s) {
  const auto truth = o.truth.AsArray();
  nlohmann::json j = {{"runs", s.runs.size()}, {"hours", o.hours},
                      {"rate_hz", o.rate_hz},  {"samples_per_run", s.samples_per_run},
                      {"failed", s.failed},    {"mean_fit_points", s.mean_fit_points},
                      {"passed", s.Passed()},  {"terms", nlohmann::json::object()}};
  for (int k = 0; k < kIeeeTerms; ++k) {
    const auto& t = s.terms[static_cast<size_t>(k)];
    j["terms"][IeeeTermName(k)] = {{"truth", truth[static_cast<size_t>(k)]},
                                   {"mean_value", t.mean_value},
                                   {"mean_sigma", t.mean_sigma},
                                   {"covered", t.covered},
                                   {"fitted", t.fitted},
                                   {"mean_z", t.mean_z},
                                   {"std_z", t.std_z},
                                   {"resolved", t.resolved}};
    const auto& i = s.independent[static_cast<size_t>(k)];
    j["independent"][IeeeTermName(k)] = {{"mean_value", i.mean_value}, {"mean_sigma", i.mean_sigma},
                                         {"covered", i.covered},       {"fitted", i.fitted},
                                         {"mean_z", i.mean_z},         {"std_z", i.std_z}};
  }
  // Every run's terms: [value, sigma, low95, high95] each, for a closer look.
  nlohmann::json per_run = nlohmann::json::array();
  for (const auto& r : s.runs) {
    nlohmann::json one = {{"ok", r.fit.ok}, {"chi2", r.fit.chi2}, {"dof", r.fit.dof}};
    for (int k = 0; k < kIeeeTerms; ++k) {
      const IeeeTermEstimate& e = r.fit.terms[static_cast<size_t>(k)];
      one[IeeeTermName(k)] = {e.value, e.sigma, e.low95, e.high95};
    }
    per_run.push_back(std::move(one));
  }
  j["per_run"] = std::move(per_run);
  fmt::print("{}\n", j.dump(1));
}

// 0, 1 as kNoiseMonteCarloManual's EXIT STATUS says.
int RunNoiseMonteCarloCommand(NoiseMonteCarloArgs* args) {
  montecarlo::NoiseMonteCarloOptions& o = args->engine;
  const int step = std::max(1, o.runs / 10);
  o.on_run = [&](int done) {
    if (!args->json && done % step == 0) fmt::print(stderr, "  {} of {} runs\n", done, o.runs);
  };
  const montecarlo::NoiseMonteCarloSummary s = montecarlo::RunNoiseMonteCarlo(o);
  if (args->json) {
    PrintJson(o, s);
  } else {
    PrintText(o, s);
  }
  return s.Passed() ? 0 : 1;
}

}  // namespace

void AddNoiseMonteCarloCommand(CLI::App* app) {
  auto a = std::make_shared<NoiseMonteCarloArgs>();
  montecarlo::NoiseMonteCarloOptions* o = &a->engine;
  auto* cmd = app->add_subcommand(
      "noise-montecarlo",
      "simulated rests with known IEEE 952 terms: the coverage of the terms' stated intervals");
  cmd->add_option("--runs", o->runs, "recordings")
      ->check(CLI::Range(2, 100000))
      ->capture_default_str();
  cmd->add_option("--hours", o->hours, "each recording's length")
      ->check(CLI::Range(0.01, 100.0))
      ->capture_default_str();
  cmd->add_option("--rate", o->rate_hz, "samples a second")
      ->check(CLI::Range(1.0, 10000.0))
      ->capture_default_str();
  cmd->add_option("--seed", o->seed, "the first run's seed")->capture_default_str();
  cmd->add_option("--jobs", o->jobs, "runs in parallel")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  cmd->add_option("--Q", o->truth.q, "quantisation, unit*s")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--N", o->truth.n, "white rate (angle random walk), unit/sqrt(Hz)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--B", o->truth.b, "bias instability (flicker), unit")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--K", o->truth.k, "rate random walk, unit/sqrt(s)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--R", o->truth.r, "rate ramp, unit/s")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_flag("--json", a->json, "the summary as JSON");
  SetManual(cmd, kNoiseMonteCarloManual);
  cmd->callback([a] { throw CLI::RuntimeError(RunNoiseMonteCarloCommand(a.get())); });
}

}  // namespace turncal::tools
