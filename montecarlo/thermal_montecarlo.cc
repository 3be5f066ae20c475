#include "montecarlo/thermal_montecarlo.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <random>

#include "core/estimation/sensor_class.h"
#include "core/estimation/thermal_calibrator.h"
#include "core/planning/pose_designs.h"
#include "montecarlo/parallel_runs.h"
#include "sim/synthetic.h"
#include "sim/thermal_truth.h"

namespace turncal::montecarlo {

namespace {

bool IsBias(const ParameterInfo& p) {
  return p.kind == ParameterKind::kSensor &&
         (p.unit == ParameterUnit::kAcceleration || p.unit == ParameterUnit::kField ||
          p.unit == ParameterUnit::kAngularRate);
}

// Mean square over the cube poses and `temps_c` of the corrected output's error with `est`.
double MeanSquareError(const MeasurementModel& model, const ThermalTruth& truth,
                       const ThermalEstimate& est, const std::vector<double>& temps_c) {
  double sum = 0.0;
  int n = 0;
  for (double t : temps_c) {
    const Eigen::VectorXd theta = truth.ThetaAt(t), theta_hat = est.ThetaAt(t);
    for (const TablePose& pose : CubePoses26()) {
      const Eigen::Vector3d raw = model.Predict(theta, pose);
      sum += (model.Correct(theta_hat, raw) - model.Correct(theta, raw)).squaredNorm() / 3.0;
      ++n;
    }
  }
  return n > 0 ? sum / n : 0.0;
}

struct Setup {
  std::unique_ptr<MeasurementModel> model;
  SensorClass sensor;
  std::vector<double> held_out_c, grid_c;
  double t0_c = 0.0;  // the middle of the soaks: the truths' and the estimates' reference
};

void OneRun(const ThermalMonteCarloOptions& o, const Setup& s, int r, ThermalRun* out) {
  std::mt19937_64 rng(o.seed * 1000003ULL + static_cast<std::uint64_t>(r));
  const double t0 = s.t0_c;
  const ThermalTruth truth = DrawThermalTruth(*s.model, s.sensor, t0, &rng);
  std::vector<PoseRecord> records;
  double t_s = 0.0;
  for (double temp_c : o.soaks_c) {
    for (const TablePose& pose : CubePoses26()) {
      PoseRecord rec =
          SimulateRecord(*s.model, truth.ThetaAt(temp_c), pose, s.sensor, o.dwell_s, &rng);
      rec.temp_c = temp_c;
      rec.t_start_s = t_s;
      rec.t_end_s = t_s + o.dwell_s;
      t_s += 2.0 * o.dwell_s;
      records.push_back(rec);
    }
  }
  const CalibratorOptions options = OptionsForClass(*s.model, s.sensor);
  ThermalOptions thermal;
  thermal.t0_c = t0;
  thermal.drop_below_sigmas = o.drop_below_sigmas;
  if (o.orders == "truth") thermal.orders = truth.basis.orders;
  if (o.orders == "full") thermal.orders.assign(truth.basis.orders.size(), thermal.max_order);
  const auto start = std::chrono::steady_clock::now();
  const ThermalEstimate est = CalibrateOverTemperature(options, records, thermal);
  out->solve_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  if (!est.ok) {
    out->error = est.error;
    return;
  }
  if (o.orders == "truth") {
    if (est.coefficients.size() != truth.coefficients.size()) {
      out->error = "the fit lowered an order below the truth's (the soaks do not carry it)";
      return;
    }
    out->z = (est.coefficients - truth.coefficients).cwiseQuotient(est.sigma);
  }
  out->z_held.resize(static_cast<Eigen::Index>(s.held_out_c.size()) * s.model->num_parameters());
  Eigen::Index k = 0;
  for (double t : s.held_out_c) {
    const Eigen::VectorXd z = (est.ThetaAt(t) - truth.ThetaAt(t)).cwiseQuotient(est.SigmaAt(t));
    out->z_held.segment(k, z.size()) = z;
    k += z.size();
  }
  out->p_value = est.p_value;
  out->ms_error_full = MeanSquareError(*s.model, truth, est, s.grid_c);
  ThermalOptions offsets;
  offsets.t0_c = t0;
  for (const ParameterInfo& p : s.model->parameters()) offsets.orders.push_back(IsBias(p) ? 3 : 0);
  const ThermalEstimate px4 = CalibrateOverTemperature(options, records, offsets);
  out->ms_error_offset_only =
      px4.ok ? MeanSquareError(*s.model, truth, px4, s.grid_c) : std::nan("");
  out->ok = true;
}

}  // namespace

bool ThermalMonteCarloSummary::Passed() const {
  if (!error.empty() || solved != static_cast<int>(runs.size())) return false;
  for (int i = 0; i < z.parameters(); ++i) {
    if (!z.Honest(i)) return false;
  }
  for (int i = 0; i < z_held.parameters(); ++i) {
    if (!z_held.Honest(i)) return false;
  }
  return ks.p > 0.01;
}

ThermalMonteCarloSummary RunThermalMonteCarlo(const ThermalMonteCarloOptions& o) {
  ThermalMonteCarloSummary s;
  Setup setup;
  std::string error;
  setup.model = MakeModel(o.model, ModelContext{}, &error);
  if (!setup.model) {
    s.error = error;
    return s;
  }
  if (!SensorClassByName(o.sensor_class, &setup.sensor)) {
    s.error = fmt::format("unknown sensor class '{}'", o.sensor_class);
    return s;
  }
  if (o.soaks_c.size() < 2) {
    s.error = "a calibration over temperature needs at least two soak temperatures";
    return s;
  }
  for (double t : o.soaks_c) {
    if (!std::isfinite(t)) {
      s.error = "the soak temperatures must be finite";
      return s;
    }
  }
  if (o.orders != "truth" && o.orders != "chosen" && o.orders != "full") {
    s.error = fmt::format("orders '{}': truth, chosen or full", o.orders);
    return s;
  }
  std::vector<double> soaks = o.soaks_c;
  std::sort(soaks.begin(), soaks.end());
  setup.held_out_c = o.held_out_c;
  if (setup.held_out_c.empty()) {
    for (std::size_t i = 1; i < soaks.size(); ++i) {
      setup.held_out_c.push_back(0.5 * (soaks[i - 1] + soaks[i]));
    }
  }
  for (int i = 0; i <= 20; ++i) {
    setup.grid_c.push_back(soaks.front() + (soaks.back() - soaks.front()) * i / 20.0);
  }
  const std::vector<ParameterInfo>& params = setup.model->parameters();
  for (double t : setup.held_out_c) {
    for (const auto& p : params) s.held_out.push_back(fmt::format("{} at {:g} degC", p.name, t));
  }
  setup.t0_c = 0.5 * (soaks.front() + soaks.back());
  if (o.orders == "truth") {
    const ThermalBasis shape = ThermalTruthBasis(*setup.model, setup.sensor, setup.t0_c);
    // The coefficients are compared with the truth's one by one: the soaks must carry its
    // highest order (n + 1 distinct temperatures for order n), or the fit lowers it.
    const int truth_order = *std::max_element(shape.orders.begin(), shape.orders.end());
    std::vector<double> temps = soaks;
    const auto distinct = static_cast<int>(std::unique(temps.begin(), temps.end()) - temps.begin());
    if (distinct <= truth_order) {
      s.error = fmt::format(
          "--thermal-orders truth compares the coefficients with the truth's polynomials of "
          "order {}: that needs at least {} distinct soak temperatures (given {}); add soaks or "
          "use --thermal-orders chosen",
          truth_order, truth_order + 1, distinct);
      return s;
    }
    for (int j = 0; j < shape.num_coefficients(); ++j) {
      s.coefficients.push_back(shape.CoefficientName(params, j));
    }
  }
  const SensorKind kind = setup.model->sensor();
  s.unit = kind == SensorKind::kAccelerometer ? "m/s^2"
           : kind == SensorKind::kGyroscope   ? "rad/s"
                                              : "Gauss";
  s.class_noise = kind == SensorKind::kAccelerometer
                      ? setup.sensor.acc_noise_density / std::sqrt(2.0 * o.dwell_s)
                  : kind == SensorKind::kGyroscope
                      ? setup.sensor.gyr_noise_density / std::sqrt(2.0 * o.dwell_s)
                      : setup.sensor.mag_noise_rms / std::sqrt(o.dwell_s * setup.sensor.rate_hz);
  s.runs = RunInParallel<ThermalRun>(o.runs, o.jobs,
                                     [&](int r, ThermalRun* out) { OneRun(o, setup, r, out); });
  s.z = ZScoreSummary(static_cast<int>(s.coefficients.size()));
  s.z_held = ZScoreSummary(static_cast<int>(s.held_out.size()));
  double full = 0.0, px4 = 0.0, ms = 0.0;
  int px4_n = 0;
  std::vector<double> p_values;
  for (const auto& r : s.runs) {
    if (!r.ok) {
      if (s.first_error.empty()) s.first_error = r.error;
      continue;
    }
    ++s.solved;
    if (r.z.size() == s.z.parameters()) s.z.Add(r.z);
    s.z_held.Add(r.z_held);
    p_values.push_back(r.p_value);
    full += r.ms_error_full;
    ms += r.solve_ms;
    if (std::isfinite(r.ms_error_offset_only)) px4 += r.ms_error_offset_only, ++px4_n;
  }
  if (s.solved > 0) {
    s.rms_error_full = std::sqrt(full / s.solved);
    s.mean_solve_ms = ms / s.solved;
    s.ks = KsUniform(p_values);
  }
  if (px4_n > 0) s.rms_error_offset_only = std::sqrt(px4 / px4_n);
  return s;
}

}  // namespace turncal::montecarlo
