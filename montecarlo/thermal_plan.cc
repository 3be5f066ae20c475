#include "montecarlo/thermal_plan.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <deque>
#include <functional>
#include <memory>
#include <random>

#include "core/analysis/publish_gate.h"
#include "core/analysis/thermal_gate.h"
#include "core/estimation/sensor_class.h"
#include "core/estimation/thermal_calibrator.h"
#include "core/planning/pose_designs.h"
#include "core/planning/table_motion.h"
#include "montecarlo/parallel_runs.h"
#include "sim/synthetic.h"
#include "sim/thermal_truth.h"

namespace turncal::montecarlo {

bool ThermalPlanOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    *error = m;
    return false;
  };
  if (!(t_hi_c - t_lo_c >= 10.0)) return fail("the range must span at least 10 degC");
  if (!(chamber_max_rate_c_per_min > 0)) return fail("the chamber's rate must be > 0");
  if (!(die_tau_s > 0)) return fail("the die's tau must be > 0");
  if (!(dwell_s > 0)) return fail("the dwell must be > 0");
  if (plateaus < 3) return fail("the classic procedure needs at least 3 plateaus");
  for (double r : ramp_rates_c_per_min) {
    if (!(r > 0) || r > chamber_max_rate_c_per_min) {
      return fail(fmt::format("ramp rate {:g} degC/min: must be > 0 and at most the chamber's {:g}",
                              r, chamber_max_rate_c_per_min));
    }
  }
  if (!(soak_rate_c_per_min > 0) || !(soak_window_s > 0)) return fail("the soak test's limits");
  if (!(coverage_c >= 0) || refit_every < 1 || runs < 1) return fail("coverage, refit or runs");
  if (!(overshoot_c >= 0)) return fail("the overshoot must be >= 0");
  for (int e : end_cubes) {
    if (e < 0 || e > 10) return fail(fmt::format("end cubes {}: must be 0 .. 10", e));
  }
  return true;
}

int ThermalProcedureOutcome::failures() const {
  return static_cast<int>(
      std::count_if(seconds.begin(), seconds.end(), [](double s) { return s < 0; }));
}

namespace {

std::vector<double> Passed(const std::vector<double>& seconds) {
  std::vector<double> v;
  for (double s : seconds)
    if (s >= 0) v.push_back(s);
  std::sort(v.begin(), v.end());
  return v;
}

}  // namespace

double ThermalProcedureOutcome::median_seconds() const {
  const std::vector<double> v = Passed(seconds);
  if (v.empty()) return NAN;
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}
double ThermalProcedureOutcome::max_seconds() const {
  const std::vector<double> v = Passed(seconds);
  return v.empty() ? NAN : v.back();
}
double ThermalProcedureOutcome::min_seconds() const {
  const std::vector<double> v = Passed(seconds);
  return v.empty() ? NAN : v.front();
}

namespace {

struct Setup {
  const ThermalPlanOptions* o = nullptr;
  std::unique_ptr<MeasurementModel> model;
  SensorClass sensor;
  SensorClass white_only;  // the class without its bias instability (the wander is simulated)
  BiasDrift drift;         // the wander the class has, which the calibrator models
  GateOptions gate;
  ThermalGateOptions thermal_gate;
  CalibratorOptions calibrator;
  ThermalOptions thermal;
  double move_s = 0.0;  // table seconds per pose besides the dwell
};

// The chamber's air (moving toward its set-point at its rate) and the die behind it, in 1-s steps,
// with the die's last soak window kept for the soak test.
class Chamber {
 public:
  Chamber(double start_c, double tau_s, double window_s)
      : air_c_(start_c),
        die_c_(start_c),
        tau_s_(tau_s),
        window_(static_cast<std::size_t>(window_s)) {}
  void Set(double setpoint_c, double rate_c_per_min) {
    setpoint_c_ = setpoint_c;
    rate_c_per_s_ = rate_c_per_min / 60.0;
  }
  // Advances `seconds` (whole steps); returns the die's mean over them.
  double Advance(double seconds) {
    const int steps = std::max(1, static_cast<int>(std::lround(seconds)));
    const double dt = seconds / steps;
    double sum = 0.0;
    for (int i = 0; i < steps; ++i) {
      const double step = rate_c_per_s_ * dt;
      air_c_ = air_c_ < setpoint_c_ ? std::min(setpoint_c_, air_c_ + step)
                                    : std::max(setpoint_c_, air_c_ - step);
      die_c_ = air_c_ + (die_c_ - air_c_) * std::exp(-dt / tau_s_);
      sum += die_c_;
      history_.push_back(die_c_);
      if (history_.size() > window_ + 1) history_.pop_front();
      t_s_ += dt;
    }
    return sum / steps;
  }
  // The soak test: the air at its set-point and the die's slope over the window below the limit.
  bool Settled(double limit_c_per_min) const {
    if (air_c_ != setpoint_c_ || history_.size() <= window_) return false;
    const double slope = (history_.back() - history_.front()) / static_cast<double>(window_);
    return std::abs(slope) * 60.0 < limit_c_per_min;
  }
  double t_s() const { return t_s_; }
  double die_c() const { return die_c_; }

 private:
  double air_c_, die_c_, tau_s_;
  std::size_t window_;
  double setpoint_c_ = 0.0, rate_c_per_s_ = 0.0, t_s_ = 0.0;
  std::deque<double> history_;
};

// One session's poses, the fit and the gate as they come.
class Session {
 public:
  Session(const Setup& s, const ThermalTruth& truth, std::uint64_t noise_seed)
      : s_(s), truth_(truth), rng_(noise_seed) {
    for (int k = 0; k < 3; ++k) wander_[k] = s_.drift.gm_sigma[k] * normal_(rng_);
  }
  // Takes the next cube pose (its move, then its dwell); true once the gate has passed.
  bool TakePose(Chamber* chamber) {
    const std::vector<TablePose>& cube = CubePoses26();
    const TablePose& pose = cube[records_.size() % cube.size()];
    chamber->Advance(s_.move_s);
    const double t0 = chamber->t_s();
    const double die_c = chamber->Advance(s_.o->dwell_s);
    // The bias's wander in time (the class's Gauss-Markov process and random walk) averaged over
    // the dwell, as the calibrator's drift model has it; SimulateRecord's own pose offsets are off
    // (s_.white_only).
    const Eigen::Vector3d wander_mean = AdvanceWander(t0, chamber->t_s());
    PoseRecord rec =
        SimulateRecord(*s_.model, truth_.ThetaAt(die_c), pose, s_.white_only, s_.o->dwell_s, &rng_);
    (s_.model->sensor() == SensorKind::kAccelerometer ? rec.acc : rec.mag)->mean += wander_mean;
    rec.temp_c = die_c;
    rec.t_start_s = t0;
    rec.t_end_s = chamber->t_s();
    records_.push_back(rec);
    lo_c_ = std::min(lo_c_, die_c);
    hi_c_ = std::max(hi_c_, die_c);
    const bool covered =
        lo_c_ <= s_.o->t_lo_c + s_.o->coverage_c && hi_c_ >= s_.o->t_hi_c - s_.o->coverage_c;
    // Fits cost O(poses^3) with the drift model: at most every tenth of the poses.
    const int every = std::max(s_.o->refit_every, static_cast<int>(records_.size()) / 10);
    if (!covered || ++since_fit_ < every) return false;
    since_fit_ = 0;
    const ThermalEstimate e = CalibrateOverTemperature(s_.calibrator, records_, s_.thermal);
    if (!e.ok) {
      last_reason_ = e.error;
      return false;
    }
    last_chi2_p_ = e.p_value;
    const GateResult g = EvaluateThermalGate(*s_.model, e, s_.gate, s_.thermal_gate);
    if (!g.pass && !g.reasons.empty()) last_reason_ = g.reasons.front();
    return g.pass;
  }
  int poses() const { return static_cast<int>(records_.size()); }
  const std::string& last_reason() const { return last_reason_; }
  double last_chi2_p() const { return last_chi2_p_; }

 private:
  // Moves the wander to t0_s, then through [t0_s, t1_s] in steps of at most 0.1 s; returns its
  // mean over that window (the trapezoid rule over the steps).
  Eigen::Vector3d AdvanceWander(double t0_s, double t1_s) {
    Step(t0_s - wander_t_s_);
    const int steps = std::max(1, static_cast<int>(std::ceil((t1_s - t0_s) / 0.1)));
    const double h = (t1_s - t0_s) / steps;
    Eigen::Vector3d sum = 0.5 * wander_;
    for (int i = 0; i < steps; ++i) {
      Step(h);
      sum += (i + 1 < steps ? 1.0 : 0.5) * wander_;
    }
    return sum / steps;
  }
  void Step(double dt) {
    if (!(dt > 0)) return;
    wander_t_s_ += dt;
    for (int k = 0; k < 3; ++k) {
      const double a = std::exp(-dt / s_.drift.gm_tau_s);
      wander_[k] = a * wander_[k] + s_.drift.gm_sigma[k] * std::sqrt(1 - a * a) * normal_(rng_) +
                   s_.drift.rw_density[k] * std::sqrt(dt) * normal_(rng_);
    }
  }

  const Setup& s_;
  const ThermalTruth& truth_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_;
  Eigen::Vector3d wander_ = Eigen::Vector3d::Zero();
  double wander_t_s_ = 0.0;
  std::vector<PoseRecord> records_;
  double lo_c_ = INFINITY, hi_c_ = -INFINITY;
  int since_fit_ = 0;
  std::string last_reason_;
  double last_chi2_p_ = NAN;
};

struct RunResult {
  double seconds = -1.0;
  int poses = 0;
  std::string reason;
  int legs = 1;         // a ramp's legs between the ends (up, down, up, ...)
  double chi2_p = NAN;  // the last fit's
};

RunResult Classic(const Setup& s, const ThermalTruth& truth, std::uint64_t noise_seed, int cubes) {
  const ThermalPlanOptions& o = *s.o;
  Chamber chamber(o.t_lo_c, o.die_tau_s, o.soak_window_s);
  Session session(s, truth, noise_seed);
  for (int k = 0; k < o.plateaus; ++k) {
    const double setpoint = o.t_lo_c + (o.t_hi_c - o.t_lo_c) * k / (o.plateaus - 1);
    chamber.Set(setpoint, o.chamber_max_rate_c_per_min);
    if (k > 0) {
      while (!chamber.Settled(o.soak_rate_c_per_min)) chamber.Advance(1.0);
    }
    for (std::size_t p = 0; p < cubes * CubePoses26().size(); ++p) {
      if (session.TakePose(&chamber))
        return {chamber.t_s(), session.poses(), "", 1, session.last_chi2_p()};
    }
  }
  return {-1.0, session.poses(), session.last_reason(), 1, session.last_chi2_p()};
}

RunResult Ramp(const Setup& s, const ThermalTruth& truth, std::uint64_t noise_seed,
               double rate_c_per_min, int end_cubes, double give_up_s) {
  const ThermalPlanOptions& o = *s.o;
  Chamber chamber(o.t_lo_c, o.die_tau_s, o.soak_window_s);
  Session session(s, truth, noise_seed);
  // The device starts soaked at the low end: the cube there end_cubes times before the ramp.
  chamber.Set(o.t_lo_c, rate_c_per_min);
  const int per_end = 26 * std::max(1, end_cubes);
  for (int k = 0; k < 26 * end_cubes; ++k) {
    if (session.TakePose(&chamber))
      return {chamber.t_s(), session.poses(), "", 1, session.last_chi2_p()};
  }
  double setpoint = o.t_hi_c;  // the end the chamber is heading for
  chamber.Set(setpoint + o.overshoot_c, rate_c_per_min);
  // Up to kMaxLegs legs between the ends (each the ramp, the die's approach and a cube there),
  // and no longer than `give_up_s` (the classic procedure's time: a plan must be quicker).
  constexpr int kMaxLegs = 3;
  int legs = 1, arrived_at = -1;  // the poses when the die reached this leg's end
  const double leg_s = (o.t_hi_c - o.t_lo_c) / rate_c_per_min * 60.0 + 6.0 * o.die_tau_s +
                       per_end * (s.move_s + o.dwell_s);
  while (chamber.t_s() < std::min(kMaxLegs * leg_s, give_up_s)) {
    if (session.TakePose(&chamber))
      return {chamber.t_s(), session.poses(), "", legs, session.last_chi2_p()};
    // The die at the end (or, with an overshoot, past it): the air back to the end, and one more
    // cycle of the cube there; a gate that still fails sends the chamber to the other end.
    const bool up = setpoint == o.t_hi_c;
    const bool at_end = up ? chamber.die_c() >= setpoint - o.coverage_c
                           : chamber.die_c() <= setpoint + o.coverage_c;
    if (at_end && arrived_at < 0) {
      arrived_at = session.poses();
      if (o.overshoot_c > 0) chamber.Set(setpoint, o.chamber_max_rate_c_per_min);
    }
    if (arrived_at >= 0 && session.poses() - arrived_at >= per_end && legs < kMaxLegs) {
      setpoint = up ? o.t_lo_c : o.t_hi_c;
      chamber.Set(up ? setpoint - o.overshoot_c : setpoint + o.overshoot_c, rate_c_per_min);
      arrived_at = -1;
      ++legs;
    }
  }
  if (chamber.t_s() >= give_up_s) {
    // Stopped at a quicker procedure's time: slower cannot be the plan.
    return {-1.0, session.poses(),
            fmt::format("stopped at {:.2f} h, a quicker procedure's time{}", give_up_s / 3600.0,
                        session.last_reason().empty() ? "" : "; " + session.last_reason()),
            legs, session.last_chi2_p()};
  }
  return {-1.0, session.poses(), session.last_reason(), legs, session.last_chi2_p()};
}

std::string Format(double v) { return fmt::format("{:g}", std::round(v * 100.0) / 100.0); }

}  // namespace

ThermalPlan PlanOverTemperature(const ThermalPlanOptions& o) {
  ThermalPlan plan;
  if (!o.IsValid(&plan.error)) return plan;
  Setup s;
  s.o = &o;
  s.model = MakeModel(o.model, ModelContext{}, &plan.error);
  if (!s.model) return plan;
  if (s.model->sensor() == SensorKind::kGyroscope) {
    plan.error = o.model + ": a gyroscope's calibration needs rate segments, which this planner " +
                 "does not yet schedule (accel13 and mag13 are planned)";
    return plan;
  }
  if (!SensorClassByName(o.sensor_class, &s.sensor) ||
      !GateDefaultsForClass(o.sensor_class, &s.gate)) {
    plan.error = "unknown sensor class '" + o.sensor_class + "'";
    return plan;
  }
  // As the station calibrates (drift_model on): the class's bias drift in time, by GLS.
  s.calibrator = DriftOptionsForClass(*s.model, s.sensor);
  s.drift = s.calibrator.drift;
  s.white_only = s.sensor;
  s.white_only.acc_bias_instability = 0.0;
  s.white_only.mag_bias_instability = 0.0;
  s.white_only.gyr_bias_instability = 0.0;
  s.thermal.t0_c = 0.5 * (o.t_lo_c + o.t_hi_c);
  s.thermal_gate.min_span_c = std::min(10.0, o.t_hi_c - o.t_lo_c - 2.0 * o.coverage_c);
  const std::vector<TablePose>& cube = CubePoses26();
  const double cycle_s = TableMotion{}.DwellWindows(cube, o.dwell_s).back().t1_s;
  s.move_s = cycle_s / static_cast<double>(cube.size()) - o.dwell_s;
  plan.pose_s = s.move_s + o.dwell_s;

  // Every procedure sees the same devices and the same noise streams (run r: seed + r).
  auto simulate = [&](double rate_c_per_min, int cubes, double give_up_s) {
    // A ramp's `cubes` are its end cubes; the classic procedure's, per plateau.
    return RunInParallel<RunResult>(o.runs, o.jobs, [&](int run, RunResult* out) {
      std::mt19937_64 truth_rng(o.seed * 1000003ULL + static_cast<std::uint64_t>(run));
      const ThermalTruth truth = DrawThermalTruth(*s.model, s.sensor, s.thermal.t0_c, &truth_rng);
      const std::uint64_t noise_seed = o.seed * 7919ULL + static_cast<std::uint64_t>(run) * 31ULL;
      *out = rate_c_per_min > 0 ? Ramp(s, truth, noise_seed, rate_c_per_min, cubes, give_up_s)
                                : Classic(s, truth, noise_seed, cubes);
    });
  };
  auto take = [](const std::vector<RunResult>& results, ThermalProcedureOutcome* out) {
    for (const RunResult& r : results) {
      out->seconds.push_back(r.seconds);
      out->poses.push_back(r.poses);
      out->chi2_p.push_back(r.chi2_p);
      out->legs = std::max(out->legs, r.legs);
      if (r.seconds < 0 && !r.reason.empty()) out->last_reason = r.reason;
    }
  };
  // The classic procedure as a lab would repeat it until it passes: the cube once at each
  // plateau, else twice, else three times.
  for (int cubes = 1; cubes <= 3; ++cubes) {
    plan.classic = ThermalProcedureOutcome{};
    plan.classic.cubes = cubes;
    take(simulate(0.0, cubes, INFINITY), &plan.classic);
    if (plan.classic.failures() == 0) break;
  }
  std::string soaks;
  for (int k = 0; k < o.plateaus; ++k) {
    const double setpoint = o.t_lo_c + (o.t_hi_c - o.t_lo_c) * k / (o.plateaus - 1);
    soaks += (k ? ", " : "") + Format(setpoint);
  }
  plan.classic.name = fmt::format("classic: {} soaks ({} degC) x {} poses", o.plateaus, soaks,
                                  26 * plan.classic.cubes);
  // The classic profile in the simulator's syntax: each plateau held for the die to settle (the
  // soak test on the die alone, which is deterministic) and the cube's poses.
  {
    Chamber dry(o.t_lo_c, o.die_tau_s, o.soak_window_s);
    const double poses_s = static_cast<double>(plan.classic.cubes * cube.size()) * plan.pose_s;
    plan.classic.chamber = fmt::format("{}; soak {} {}", Format(o.t_lo_c), Format(o.t_lo_c),
                                       Format(std::ceil(poses_s)));
    dry.Advance(poses_s);
    for (int k = 1; k < o.plateaus; ++k) {
      const double setpoint = o.t_lo_c + (o.t_hi_c - o.t_lo_c) * k / (o.plateaus - 1);
      dry.Set(setpoint, o.chamber_max_rate_c_per_min);
      const double ramp_s = std::abs(setpoint - dry.die_c()) / o.chamber_max_rate_c_per_min * 60.0;
      const double start_s = dry.t_s();
      while (!dry.Settled(o.soak_rate_c_per_min)) dry.Advance(1.0);
      const double hold_s = dry.t_s() - start_s - ramp_s + poses_s;
      dry.Advance(poses_s);
      plan.classic.chamber +=
          fmt::format("; ramp {} {} {}", Format(setpoint), Format(o.chamber_max_rate_c_per_min),
                      Format(std::ceil(std::max(hold_s, 0.0))));
    }
  }
  // The ramps, the fastest first: a slower one whose ramp alone takes longer than the quickest
  // passing plan so far cannot be quicker and is not simulated.
  std::vector<double> rates = o.ramp_rates_c_per_min;
  std::sort(rates.begin(), rates.end(), std::greater<double>());
  // No ramp runs longer than the classic procedure took (when it passed).
  double best_s = plan.classic.failures() == 0 ? plan.classic.max_seconds() : INFINITY;
  const double end_s = 26.0 * plan.pose_s;  // a cube's table time
  for (double r : rates) {
    for (int e : o.end_cubes) {
      ThermalProcedureOutcome ramp;
      ramp.name = e == 0 ? fmt::format("ramp {} degC/min, the cube cycled", Format(r))
                         : fmt::format("ramp {} degC/min, the cube cycled, {} cube{} at each end",
                                       Format(r), e, e > 1 ? "s" : "");
      ramp.rate_c_per_min = r;
      ramp.end_cubes = e;
      if ((o.t_hi_c - o.t_lo_c) / r * 60.0 + 2.0 * e * end_s >= best_s) {
        ramp.skipped = true;
      } else {
        take(simulate(r, e, best_s), &ramp);
        if (ramp.failures() == 0) best_s = std::min(best_s, ramp.max_seconds());
      }
      plan.ramps.push_back(ramp);
    }
  }
  for (ThermalProcedureOutcome& r : plan.ramps) {
    // The profile of the slowest run: its legs between the ends.
    r.chamber = Format(o.t_lo_c);
    if (r.end_cubes > 0) {
      r.chamber +=
          fmt::format("; soak {} {}", Format(o.t_lo_c), Format(std::ceil(r.end_cubes * end_s)));
    }
    for (int leg = 0; leg < r.legs; ++leg) {
      const double end = leg % 2 ? o.t_lo_c : o.t_hi_c;
      const double past = leg % 2 ? end - o.overshoot_c : end + o.overshoot_c;
      r.chamber += fmt::format("; ramp {} {}", Format(past), Format(r.rate_c_per_min));
      if (r.end_cubes > 0 && o.overshoot_c <= 0) {
        // Held for the die's approach (from r tau / 60 behind to within the coverage) and the
        // cubes.
        const double lag_c = r.rate_c_per_min * o.die_tau_s / 60.0;
        const double approach_s = o.die_tau_s * std::log(std::max(1.0, lag_c / o.coverage_c));
        r.chamber += fmt::format(" {}", Format(std::ceil(approach_s + r.end_cubes * end_s)));
      }
      if (o.overshoot_c > 0) {
        r.chamber += fmt::format(" (until the die is within {} degC of {}); ramp {} {}",
                                 Format(o.coverage_c), Format(end), Format(end),
                                 Format(o.chamber_max_rate_c_per_min));
      }
    }
  }
  for (std::size_t k = 0; k < plan.ramps.size(); ++k) {
    const ThermalProcedureOutcome& r = plan.ramps[k];
    if (r.skipped || r.failures() > 0) continue;
    if (plan.chosen < 0 ||
        r.max_seconds() < plan.ramps[static_cast<std::size_t>(plan.chosen)].max_seconds()) {
      plan.chosen = static_cast<int>(k);
    }
  }
  return plan;
}

}  // namespace turncal::montecarlo
