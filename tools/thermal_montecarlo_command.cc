#include "tools/thermal_montecarlo_command.h"

#include <fmt/format.h>

#include "tools/z_score_table.h"

namespace turncal::tools {

void AddThermalMonteCarloOptions(CLI::App* mc, ThermalMonteCarloArgs* args) {
  mc->add_option("--thermal", args->soaks_c,
                 "calibration over temperature, in memory: the soak temperatures, degC, comma "
                 "separated (e.g. -20,5,25,45,70); the 26 cube poses at each (--model accel13, "
                 "accel12, mag13, gyro12, gyro21)")
      ->delimiter(',');
  mc->add_option("--thermal-orders", args->engine.orders,
                 "with --thermal: each parameter's order as the truth's (the coefficients' z "
                 "comparable across runs) or chosen from the data")
      ->check(CLI::IsMember({"truth", "chosen", "full"}))
      ->capture_default_str();
  mc->add_option("--thermal-drop", args->engine.drop_below_sigmas,
                 "with --thermal-orders chosen: a top coefficient within this many sigma of zero "
                 "is dropped")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  mc->add_option("--held-out", args->held_out_c,
                 "with --thermal: temperatures where every parameter is checked, degC, comma "
                 "separated (default: the midpoints between the soaks)")
      ->delimiter(',');
  mc->add_option("--thermal-jobs", args->engine.jobs, "with --thermal: runs in parallel")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
}

int RunThermalMonteCarloCommand(const ThermalMonteCarloArgs& args) {
  montecarlo::ThermalMonteCarloOptions o = args.engine;
  o.soaks_c = args.soaks_c;
  o.held_out_c = args.held_out_c;
  const montecarlo::ThermalMonteCarloSummary s = montecarlo::RunThermalMonteCarlo(o);
  if (!s.error.empty()) {
    fmt::print(stderr, "turncal montecarlo: {}\n", s.error);
    return 2;
  }
  const bool passed = s.Passed();
  if (args.json) {
    fmt::print("{}\n", nlohmann::json{{"model", o.model},
                                      {"class", o.sensor_class},
                                      {"soaks_c", o.soaks_c},
                                      {"orders", o.orders},
                                      {"runs", o.runs},
                                      {"solved", s.solved},
                                      {"ks_p", s.ks.p},
                                      {"coefficients", ZScoreRows(s.coefficients, s.z, true)},
                                      {"held_out", ZScoreRows(s.held_out, s.z_held, true)},
                                      {"rms_error_full", s.rms_error_full},
                                      {"rms_error_offset_only", s.rms_error_offset_only},
                                      {"unit", s.unit},
                                      {"passed", passed}}
                           .dump());
    return passed ? 0 : 1;
  }
  std::string soaks;
  for (double t : o.soaks_c) soaks += fmt::format("{}{:g}", soaks.empty() ? "" : ", ", t);
  fmt::print(
      "Monte Carlo over temperature: {} runs of {} ({} class), the 26 cube poses at {} degC, "
      "{:.1f} s each, orders {}, seed {}; {} solved; mean solve {:.0f} ms{}\n\n",
      o.runs, o.model, o.sensor_class, soaks, o.dwell_s, o.orders, o.seed, s.solved,
      s.mean_solve_ms, s.first_error.empty() ? "" : "; first failure: " + s.first_error);
  int bad = 0, bad_held = 0;
  if (!s.coefficients.empty()) {
    fmt::print("Coefficients (per degC^j about the range's middle):\n\n{}\n",
               ZScoreTable(s.coefficients, s.z, true, &bad));
  }
  fmt::print("Each parameter at the held-out temperatures:\n\n{}\n",
             ZScoreTable(s.held_out, s.z_held, true, &bad_held));
  fmt::print("chi^2 p-values against uniform: KS D = {:.3f}, p = {:.3g}\n", s.ks.d, s.ks.p);
  fmt::print(
      "Error left in the corrected output over the range (RMS over the runs, the cube poses and "
      "21 temperatures, {}):\n  turncal's thermal model   {:.3g}\n  offset-only cubics (PX4, "
      "ArduPilot)   {:.3g}\n  the class's white noise over one pose   {:.3g}\n",
      s.unit, s.rms_error_full, s.rms_error_offset_only, s.class_noise);
  fmt::print("\n{} of {} coefficients and {} of {} held-out values fail; {}\n", bad,
             s.coefficients.size(), bad_held, s.held_out.size(), passed ? "PASSED" : "FAILED");
  return passed ? 0 : 1;
}

}  // namespace turncal::tools
