#include "tools/free_montecarlo_command.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <nlohmann/json.hpp>

#include "montecarlo/free_montecarlo.h"
#include "tools/help_text.h"
#include "tools/z_score_table.h"

namespace turncal::tools {
namespace {

struct FreeMonteCarloArgs {
  montecarlo::FreeMonteCarloOptions engine;
  bool verbose = false;
  bool json = false;
};

// The codes RunFreeMonteCarloCommand returns.
constexpr Manual kFreeMonteCarloManual = {
    "Repeats simulated tumbles (random orientations of a three-axis table, as bytes, the "
    "announced poses ignored) through free mode, and checks a free model's sigma against "
    "its errors: mean and std of z per parameter, the count beyond 3 sigma, the chi^2 "
    "p-values against uniform, the gate. With --hand, a hand's continuous rotation instead "
    "(the magnetometer's samples in motion as data), through the station exactly as "
    "`turncald --replay FILE --once --pose-source free` runs it. It also says how often an "
    "honest sigma passes the criteria in a row of this many runs (about half the rows of 200 "
    "for nine parameters; 99 % of rows of 600): a row that misses them by a little asks for "
    "more runs.",
    "turncal free-montecarlo --model accel9 --runs 200\n"
    "turncal free-montecarlo --model gyro9 --class consumer --runs 200\n"
    "turncal free-montecarlo --model magellipsoid --cap 20 --runs 50   # low coverage\n"
    "turncal free-montecarlo --model magellipsoid --hand 10 --device-rate 1000 --mag-rate 100",
    "0 every parameter's std z in [0.9, 1.1] with |mean z| <= 0.15; 1 otherwise, or no run "
    "gave an estimate; 2 a command-line mistake",
    "docs/ACCURACY.md (\"Without a turntable\")"};

// The gate's five commonest reasons, one line each.
std::string ReasonsText(const montecarlo::FreeMonteCarloSummary& s) {
  std::string text;
  for (const auto& [count, why] : s.top_reasons) text += fmt::format("  {} runs: {}\n", count, why);
  return text;
}

// One method's hard-iron errors in mG (the simulator's field is in Gauss): RMS / median / max.
std::string ErrorsText(const montecarlo::HardIronErrors& e) {
  return e.runs == 0 ? "no fit"
                     : fmt::format("{:.3f} / {:.3f} / {:.3f} ({} runs)", 1e3 * e.rms,
                                   1e3 * e.median, 1e3 * e.max, e.runs);
}

// The hard iron's error of turncal's fit against the plain fits on the same values.
std::string HardIronText(const montecarlo::FreeMonteCarloSummary& s) {
  return fmt::format(
      "Hard iron's error |b - b_true|, mG, RMS / median / largest, on the same values:\n"
      "  turncal (its model, weighted):  {}\n"
      "  plain sphere (Kasa):            {}\n"
      "  plain ellipsoid (algebraic):    {}\n",
      ErrorsText(s.hard_iron), ErrorsText(s.plain_sphere), ErrorsText(s.plain_ellipsoid));
}

// How often an honest sigma passes the criteria in a row of this many runs, and of 600: the
// criteria are about two standard errors wide at 200 runs (montecarlo::HonestRowPassChance).
struct RowChance {
  double these = 0, of600 = 0;
};

RowChance ChanceOf(const montecarlo::FreeMonteCarloSummary& s) {
  const Eigen::MatrixXd correlation = s.z.Correlation();
  return {montecarlo::HonestRowPassChance(correlation, s.solved),
          montecarlo::HonestRowPassChance(correlation, 600)};
}

std::string ChanceText(const montecarlo::FreeMonteCarloSummary& s) {
  const RowChance c = ChanceOf(s);
  const double n = std::max(1, s.solved), widths = montecarlo::kHonestStdZBound * std::sqrt(2 * n);
  return fmt::format(
      "An honest sigma (z normal, with these parameters' correlation) passes the criteria in "
      "{:.0f} % of rows of {} runs{} (simulated): std z's bounds are {:.1f} of its standard "
      "errors (+-{:.3f}) from 1 here, mean z's {:.1f} of its (+-{:.3f}) from 0{}.\n",
      100 * c.these, s.solved,
      s.solved < 600 ? fmt::format(", in {:.0f} % of rows of 600", 100 * c.of600) : "", widths,
      1 / std::sqrt(2 * n), montecarlo::kHonestMeanZBound * std::sqrt(n), 1 / std::sqrt(n),
      widths < 3 ? "; a row that misses them by a little asks for more runs, not a verdict" : "");
}

nlohmann::json ErrorsJson(const montecarlo::HardIronErrors& e) {
  return {{"runs", e.runs},
          {"rms_mG", e.runs ? nlohmann::json(1e3 * e.rms) : nlohmann::json()},
          {"median_mG", e.runs ? nlohmann::json(1e3 * e.median) : nlohmann::json()},
          {"max_mG", e.runs ? nlohmann::json(1e3 * e.max) : nlohmann::json()}};
}

void PrintFreeJson(const montecarlo::FreeMonteCarloOptions& o,
                   const montecarlo::FreeMonteCarloSummary& s) {
  const RowChance chance = ChanceOf(s);
  fmt::print("{}\n", nlohmann::json{{"model", o.model},
                                    {"class", o.sensor_class},
                                    {"protocol", o.protocol},
                                    {"drift", o.drift},
                                    {"warmup", o.warmup},
                                    {"hand_s", o.hand_s},
                                    {"hand_rate_dps", o.hand_rate_dps},
                                    {"hand_path", o.hand_path},
                                    {"hand_pause_every_s", o.hand_pause_every_s},
                                    {"device_rate_hz", o.device_rate_hz},
                                    {"mag_rate_hz", o.mag_rate_hz},
                                    {"mag_bandwidth_hz", o.mag_bandwidth_hz},
                                    {"mag_lag_s", o.mag_lag_s},
                                    {"bandwidth_known", o.bandwidth_known},
                                    {"mag_noise_filtered", o.mag_noise_filtered},
                                    {"magnet_at_s", o.magnet_at_s},
                                    {"runs", o.runs},
                                    {"ok", s.solved},
                                    {"orientations", o.orientations},
                                    {"cap_deg", o.cap_deg},
                                    {"mean_intervals", s.intervals_mean},
                                    {"gate_passed", s.gate_passed},
                                    {"gated", s.gated},
                                    {"gate_reasons", s.top_reasons},
                                    {"ks_d", s.ks.d},
                                    {"ks_p", s.ks.p},
                                    {"norm_bias_sigmas_median", s.norm_bias_median},
                                    {"norm_bias_sigmas_max", s.norm_bias_max},
                                    {"p_value_deciles", s.p_value_deciles},
                                    {"honest_row_pass_chance", chance.these},
                                    {"honest_row_pass_chance_600", chance.of600},
                                    {"hard_iron_error",
                                     {{"turncal", ErrorsJson(s.hard_iron)},
                                      {"plain_sphere", ErrorsJson(s.plain_sphere)},
                                      {"plain_ellipsoid", ErrorsJson(s.plain_ellipsoid)}}},
                                    {"params", ZScoreRows(s.parameters, s.z, true)}}
                         .dump());
}

void PrintFreeText(const montecarlo::FreeMonteCarloOptions& o,
                   const montecarlo::FreeMonteCarloSummary& s) {
  int bad = 0;
  const std::string table = ZScoreTable(s.parameters, s.z, true, &bad);
  const std::string what =
      o.hand_s > 0
          ? fmt::format(
                "{} hand rotations ({}, {} s at {} deg/s RMS{}{}{}{})", o.runs, o.hand_path,
                o.hand_s, o.hand_rate_dps,
                o.hand_pause_every_s > 0
                    ? fmt::format(", a {} s pause every {} s", o.hand_pause_s, o.hand_pause_every_s)
                    : "",
                o.mag_rate_hz > 0 ? fmt::format(", magnetometer at {} Hz", o.mag_rate_hz) : "",
                o.mag_lag_s > 0 ? fmt::format(", lagging the clock by {} s", o.mag_lag_s) : "",
                o.mag_bandwidth_hz > 0
                    ? fmt::format(", its bandwidth {} Hz ({}{})", o.mag_bandwidth_hz,
                                  o.bandwidth_known ? "known to the station" : "not told",
                                  o.mag_noise_filtered ? ", the noise filtered too" : "")
                    : "")
          : fmt::format("{} tumbles of {} orientations (up within {:.0f} deg of +z)", o.runs,
                        o.orientations, o.cap_deg);
  fmt::print(
      "free {} ({} class, {}, drift {}{}), {}, each as bytes through free mode: {} estimated ({} "
      "failed{}), {:.1f} intervals on average, gate passed {} of {}\n{}\n{}\nchi^2 p-values "
      "against uniform: KS D = {:.3f}, p = {:.3g}; per tenth from 0 to 1: {}\nCriteria: std z in "
      "[0.9, 1.1] and |mean z| <= 0.15; {} of {} parameters fail.\n",
      o.model, o.sensor_class, o.protocol, o.drift,
      o.warmup > 0 ? fmt::format(", warm-up {} bias instabilities", o.warmup) : "", what, s.solved,
      o.runs - s.solved, s.first_error.empty() ? "" : ", the first: " + s.first_error,
      s.intervals_mean, s.gate_passed, s.gated,
      s.top_reasons.empty() ? "" : "refused for:\n" + ReasonsText(s), table, s.ks.d, s.ks.p,
      fmt::join(s.p_value_deciles, " "), bad, s.parameters.size());
  fmt::print("{}", ChanceText(s));
  if (s.norm_bias_max > 0) {
    fmt::print(
        "Second-order bias from the values' noise, removed from each fit (its largest parameter, "
        "in "
        "sigmas): median {:.2f}, largest {:.2f}\n",
        s.norm_bias_median, s.norm_bias_max);
  }
  if (s.hard_iron.runs > 0) fmt::print("{}", HardIronText(s));
}

// Every run's estimate, truth, sigma and z on standard error (--verbose), and the progress.
void ReportRun(const FreeMonteCarloArgs& args, const std::vector<std::string>& names, int run,
               const montecarlo::FreeRun& r, int scored) {
  for (std::size_t i = 0; args.verbose && i < names.size(); ++i) {
    const auto k = static_cast<Eigen::Index>(i);
    fmt::print(stderr,
               "run {} {} est {:.9g} truth {:.9g} sigma {:.3g} z {:+.2f} gate {} bias removed "
               "{:.2f} sigma\n",
               run, names[i], r.theta[k], r.truth[k], r.sigma[k], r.z[k],
               !r.gated ? "none"
               : r.gate ? "pass"
                        : "refused",
               r.norm_bias_sigmas);
  }
  if (!args.json && scored % std::max(1, args.engine.runs / 10) == 0) {
    fmt::print(stderr, "  {} of {} runs\n", scored, args.engine.runs);
  }
}

// 0 when every parameter is honest; 1 otherwise or when fewer than two runs gave an estimate;
// 2 when an option cannot work (kFreeMonteCarloManual's EXIT STATUS).
int RunFreeMonteCarloCommand(const FreeMonteCarloArgs& args) {
  montecarlo::FreeMonteCarloOptions options = args.engine;
  options.on_run = [&](int run, const montecarlo::FreeRun& r, int scored,
                       const std::vector<std::string>& names) {
    ReportRun(args, names, run, r, scored);
  };
  const montecarlo::FreeMonteCarloSummary s = montecarlo::RunFreeMonteCarlo(options);
  if (!s.error.empty()) {
    fmt::print(stderr, "turncal free-montecarlo: {}\n", s.error);
    return 2;
  }
  if (s.solved < 2) {
    fmt::print(stderr, "turncal free-montecarlo: {} of {} runs gave an estimate ({})\n", s.solved,
               options.runs, s.first_error);
    if (s.gated > 0) {
      fmt::print("the gate passed {} of {} runs{}\n{}", s.gate_passed, s.gated,
                 s.top_reasons.empty() ? "" : "; it refused for", ReasonsText(s));
    }
    return 1;
  }
  if (args.json) {
    PrintFreeJson(options, s);
  } else {
    PrintFreeText(options, s);
  }
  return s.Passed() ? 0 : 1;
}

}  // namespace

void AddFreeMonteCarloCommand(CLI::App* app) {
  auto a = std::make_shared<FreeMonteCarloArgs>();
  montecarlo::FreeMonteCarloOptions* o = &a->engine;
  auto* cmd = app->add_subcommand(
      "free-montecarlo",
      "repeat simulated tumbles as bytes through free mode and check the free models' sigma");
  cmd->add_option("--model", o->model, "accel9 | gyro9 | gyro9g | magellipsoid | accmag")
      ->check(CLI::IsMember({"accel9", "gyro9", "gyro9g", "magellipsoid", "accmag"}))
      ->capture_default_str();
  cmd->add_option("--class", o->sensor_class, "industrial | consumer (SENSORS.md)")
      ->check(CLI::IsMember({"industrial", "consumer"}))
      ->capture_default_str();
  cmd->add_option("--protocol", o->protocol, "mip | gx2 | xbus | xbus-legacy")
      ->capture_default_str();
  cmd->add_option("--runs", o->runs, "tumbles")
      ->check(CLI::Range(2, 100000))
      ->capture_default_str();
  cmd->add_option("--seed", o->seed, "the first run's seed")->capture_default_str();
  cmd->add_option("--jobs", o->jobs, "runs in parallel")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  cmd->add_option("--orientations", o->orientations, "static orientations per tumble")
      ->check(CLI::Range(4, 1000))
      ->capture_default_str();
  cmd->add_option("--dwell", o->dwell_s, "seconds still per orientation")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--cap", o->cap_deg,
                  "up within this many degrees of the table's +z (180: anywhere; small: low "
                  "coverage)")
      ->check(CLI::Range(0.0, 180.0))
      ->capture_default_str();
  cmd->add_flag(
      "--field-unknown", [o](std::int64_t) { o->field_known = false; },
      "the magnetometer models without the field's magnitude (relative scale)");
  cmd->add_option("--drift", o->drift,
                  "the station's model of the bias wander ([station] drift_model): gauss-markov "
                  "(the class's, a process in time) or independent (an offset per interval of "
                  "the class's bias instability)")
      ->check(CLI::IsMember({"gauss-markov", "independent"}))
      ->capture_default_str();
  cmd->add_option("--warmup", o->warmup,
                  "a warm-up after power-on of this many bias instabilities (every triad, the "
                  "gyroscope's too), simulated and allowed for by the station")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--warmup-tau", o->warmup_tau_s, "the warm-up's time constant, s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--hand", o->hand_s,
                  "a hand's continuous rotation of this many seconds instead of the table's "
                  "orientations (magellipsoid, accmag): the magnetometer's samples in motion as "
                  "data, as `turncal free` fits them")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--hand-rate", o->hand_rate_dps, "with --hand: the RMS rate, deg/s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--hand-path", o->hand_path, "with --hand: tumble, figure8 or planar")
      ->check(CLI::IsMember({"tumble", "figure8", "planar"}))
      ->capture_default_str();
  cmd->add_option("--hand-pauses", o->hand_pause_every_s,
                  "with --hand: a pause after every this many seconds of motion (0: none)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--magnet", o->magnet_at_s,
                  "a magnet passes by this many seconds into each session (turncal sim "
                  "--magnet): the disturbed values must be left out")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--magnet-s", o->magnet_s, "with --magnet: how long it is near, s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--magnet-peak", o->magnet_peak, "with --magnet: its peak field, Gauss")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--hand-pause", o->hand_pause_s, "with --hand-pauses: each pause, s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--device-rate", o->device_rate_hz,
                  "the device's sample rate, Hz (default: the protocol's)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--mag-rate", o->mag_rate_hz,
                  "the magnetometer's own rate, Hz: below the device's it holds its value "
                  "between updates (default: a new value in every sample)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--mag-lag", o->mag_lag_s,
                  "the magnetometer's lag behind the stream's clock, s (not told to the "
                  "station: the norm does not see it)")
      ->check(CLI::Range(0.0, 1.0));
  cmd->add_option("--mag-bandwidth", o->mag_bandwidth_hz,
                  "the magnetometer's first-order low-pass, Hz (0: none), told to the station "
                  "([free] mag_bandwidth_hz)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_flag("!--bandwidth-unknown", o->bandwidth_known,
                "with --mag-bandwidth: do not tell the station (what ignoring it costs)");
  cmd->add_flag("--mag-noise-filtered", o->mag_noise_filtered,
                "with --mag-bandwidth: the noise through the filter too (correlated in time)");
  cmd->add_flag("--verbose", a->verbose,
                "every run's estimate, truth, sigma and z per parameter on standard error");
  cmd->add_flag("--json", a->json, "one JSON object");
  cmd->callback([a] { throw CLI::RuntimeError(RunFreeMonteCarloCommand(*a)); });
  SetManual(cmd, kFreeMonteCarloManual);
}

}  // namespace turncal::tools
