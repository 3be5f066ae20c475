#include "tools/plan_thermal_command.h"

#include <fmt/format.h>

#include <cmath>
#include <memory>
#include <nlohmann/json.hpp>

#include "montecarlo/thermal_plan.h"
#include "tools/help_text.h"

namespace turncal::tools {

namespace {

constexpr Manual kPlanThermalManual = {
    "Plans a calibration over temperature in chamber and table time: simulated devices in a "
    "simulated chamber (the die lagging the air), the real calibration over temperature and its "
    "gate run as the poses come, along the classic soak procedure (plateaus over the range, the "
    "26 cube poses at each once the die has settled) and along ramps of the chamber with the table "
    "cycling the cube; each procedure's time from a device soaked at the range's low end to a "
    "gate passing over the whole range. The plan is the quickest ramp that passed in every run: "
    "its chamber profile (turncal sim --chamber syntax) and its poses. In memory: white noise and "
    "the class's bias wander (averaged over each dwell, as the calibrator's drift model has it); "
    "the honesty of sigma along such sessions is turncal montecarlo --pipeline "
    "--chamber's.",
    "turncal plan-thermal --model accel13 --class industrial --range 0 40 --runs 5",
    "0; 1 no ramp passed in every run; 2 a command-line mistake", "docs/OBSERVABILITY.md"};

std::string Hours(double s) {
  return std::isfinite(s) ? fmt::format("{:.2f} h", s / 3600.0) : std::string("never");
}

nlohmann::json ToJson(const montecarlo::ThermalProcedureOutcome& p) {
  auto number = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); };
  return {{"name", p.name},
          {"chamber", p.chamber},
          {"rate_c_per_min", p.rate_c_per_min},
          {"end_cubes", p.end_cubes},
          {"seconds", p.seconds},
          {"poses", p.poses},
          {"chi2_p",
           [&] {
             nlohmann::json a = nlohmann::json::array();
             for (double v : p.chi2_p) a.push_back(number(v));
             return a;
           }()},
          {"median_s", number(p.median_seconds())},
          {"max_s", number(p.max_seconds())},
          {"never", p.failures()},
          {"skipped", p.skipped},
          {"last_reason", p.last_reason}};
}

void PrintRow(const montecarlo::ThermalProcedureOutcome& p, std::size_t runs) {
  if (p.skipped) {
    fmt::print("  {:<52} {:>6} not simulated: the ramp alone takes longer than the plan\n", p.name,
               "-");
    return;
  }
  int poses = 0, passed = 0;
  for (std::size_t i = 0; i < p.poses.size(); ++i) {
    if (p.seconds[i] >= 0) poses += p.poses[i], ++passed;
  }
  fmt::print("  {:<52} {:>6} {:>9} ({} .. {})  {}/{} passed{}\n", p.name,
             passed ? fmt::format("{:.0f}", static_cast<double>(poses) / passed) : "-",
             Hours(p.median_seconds()), Hours(p.min_seconds()), Hours(p.max_seconds()), passed,
             runs, p.failures() && !p.last_reason.empty() ? "  (" + p.last_reason + ")" : "");
}

int RunPlanThermal(const montecarlo::ThermalPlanOptions& o, bool json) {
  const montecarlo::ThermalPlan plan = montecarlo::PlanOverTemperature(o);
  if (!plan.error.empty()) {
    fmt::print(stderr, "turncal plan-thermal: {}\n", plan.error);
    return 2;
  }
  const double classic = plan.classic.max_seconds();
  const montecarlo::ThermalProcedureOutcome* chosen =
      plan.chosen >= 0 ? &plan.ramps[static_cast<std::size_t>(plan.chosen)] : nullptr;
  if (json) {
    nlohmann::json ramps = nlohmann::json::array();
    for (const auto& r : plan.ramps) ramps.push_back(ToJson(r));
    fmt::print("{}\n",
               nlohmann::json{
                   {"model", o.model},
                   {"class", o.sensor_class},
                   {"range_c", {o.t_lo_c, o.t_hi_c}},
                   {"die_tau_s", o.die_tau_s},
                   {"chamber_max_rate_c_per_min", o.chamber_max_rate_c_per_min},
                   {"dwell_s", o.dwell_s},
                   {"pose_s", plan.pose_s},
                   {"runs", o.runs},
                   {"classic", ToJson(plan.classic)},
                   {"ramps", ramps},
                   {"chosen", chosen ? nlohmann::json(chosen->name) : nlohmann::json()},
                   {"chosen_chamber", chosen ? nlohmann::json(chosen->chamber) : nlohmann::json()}}
                   .dump());
    return chosen ? 0 : 1;
  }
  fmt::print(
      "{} ({} class tolerances) over {:g} .. {:g} degC, {} simulated devices: the die {:g} s "
      "behind the air, the chamber at most {:g} degC/min, {:.1f} s of table per pose ({:g} s "
      "dwell)\n  {:<52} {:>6} {:>9} (fastest .. slowest)\n",
      o.model, o.sensor_class, o.t_lo_c, o.t_hi_c, o.runs, o.die_tau_s,
      o.chamber_max_rate_c_per_min, plan.pose_s, o.dwell_s, "procedure", "poses",
      "time to a passing gate");
  PrintRow(plan.classic, static_cast<std::size_t>(o.runs));
  for (const auto& r : plan.ramps) PrintRow(r, static_cast<std::size_t>(o.runs));
  if (!chosen) {
    fmt::print("no ramp passed the gate in every run: keep the classic procedure\n");
    return 1;
  }
  fmt::print(
      "plan: {} -- {} at most ({:.0f} % of the classic procedure's {})\n"
      "  chamber: \"{}\" (turncal sim --chamber syntax: start; ramp SETPOINT DEGC_PER_MIN)\n"
      "  table:   the 26 cube poses in turn (turncal plan's cube), {:g} s each, from the start "
      "until the gate passes\n"
      "  classic: \"{}\"\n",
      chosen->name, Hours(chosen->max_seconds()), 100.0 * chosen->max_seconds() / classic,
      Hours(classic), chosen->chamber, o.dwell_s, plan.classic.chamber);
  return 0;
}

}  // namespace

void AddPlanThermalCommand(CLI::App* app) {
  auto o = std::make_shared<montecarlo::ThermalPlanOptions>();
  auto json = std::make_shared<bool>(false);
  auto range = std::make_shared<std::vector<double>>(std::vector<double>{0.0, 40.0});
  auto* cmd = app->add_subcommand(
      "plan-thermal",
      "plan a calibration over temperature: chamber-and-table time to a passing gate along the "
      "classic soak procedure and along ramps of the chamber (simulated in memory, the real "
      "calibrator and gate)");
  SetManual(cmd, kPlanThermalManual);
  cmd->add_option("--model", o->model, "accel13 or mag13")
      ->check(CLI::IsMember({"accel13", "mag13"}))
      ->capture_default_str();
  cmd->add_option("--class", o->sensor_class, "industrial|consumer (noise, tempcos, tolerances)")
      ->check(CLI::IsMember({"industrial", "consumer"}))
      ->capture_default_str();
  cmd->add_option("--range", *range, "the range to calibrate, degC: LOW HIGH")
      ->expected(2)
      ->capture_default_str();
  cmd->add_option("--chamber-rate", o->chamber_max_rate_c_per_min,
                  "the chamber's fastest ramp, degC/min")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--die-tau", o->die_tau_s, "the die's lag behind the air, s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--overshoot", o->overshoot_c,
                  "a ramp may drive the air this far past the range's ends, degC (the die, "
                  "lagging, reaches them sooner; mind the device's rating)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--dwell", o->dwell_s, "seconds averaged per pose")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--plateaus", o->plateaus, "the classic procedure's set-points, ends included")
      ->check(CLI::Range(3, 50))
      ->capture_default_str();
  cmd->add_option("--ramp-rates", o->ramp_rates_c_per_min, "the ramps to try, degC/min")
      ->delimiter(',')
      ->capture_default_str();
  cmd->add_option("--end-cubes", o->end_cubes,
                  "each ramp also with the cube this many times at each end (the low end before "
                  "the ramp, the far end before turning back; 0: once at the far end)")
      ->delimiter(',')
      ->check(CLI::Range(0, 10))
      ->capture_default_str();
  cmd->add_option("--runs", o->runs, "simulated devices (truth and noise from seed + run)")
      ->check(CLI::Range(1, 10000))
      ->capture_default_str();
  cmd->add_option("--seed", o->seed, "first seed")->capture_default_str();
  cmd->add_option("--jobs", o->jobs, "threads")->check(CLI::Range(1, 256))->capture_default_str();
  cmd->add_flag("--json", *json, "one JSON object");
  cmd->callback([o, json, range] {
    o->t_lo_c = (*range)[0];
    o->t_hi_c = (*range)[1];
    throw CLI::RuntimeError(RunPlanThermal(*o, *json));
  });
}

}  // namespace turncal::tools
