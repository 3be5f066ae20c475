// The free models fitted in turn, with the fallback from the ellipsoid to the sphere, the models a
// set of intervals can feed, and the fit error in the vendors' terms (core/estimation/
// free_calibrator.h).

#include <fmt/format.h>

#include <algorithm>
#include <memory>

#include "core/estimation/free_calibrator.h"

namespace turncal {

bool CalibrateFreeModels(const std::vector<std::string>& models,
                         const std::vector<FreeInterval>& intervals, const FreeContext& context,
                         const FreeCalibratorOptions& options, std::vector<FreeModelResult>* out,
                         std::string* error) {
  std::vector<std::unique_ptr<FreeModel>> made;
  for (const auto& name : models) {
    auto m = MakeFreeModel(name, context, error);
    if (!m) return false;
    made.push_back(std::move(m));
  }
  FreeData data;
  data.intervals = intervals;
  data.context = context;
  auto find = [&](const std::string& name) -> const FreeModelResult* {
    for (const auto& r : *out) {
      if (r.model == name && r.estimate.estimate.ok) return &r;
    }
    return nullptr;
  };
  for (const auto& model : made) {
    FreeData d = data;
    const std::string up = model->upstream();
    if (!up.empty()) {
      if (!find(up)) {
        std::vector<FreeModelResult> upstream;
        if (!CalibrateFreeModels({up}, intervals, context, options, &upstream, error)) return false;
        for (auto& r : upstream) out->push_back(std::move(r));
      }
      if (const FreeModelResult* u = find(up)) {
        d.upstream_theta = u->estimate.estimate.theta;
        d.upstream_covariance = u->estimate.estimate.covariance;
      }
    }
    FreeModelResult r;
    r.requested = r.model = model->name();
    r.estimate = CalibrateFree(*model, d, options);
    if (!up.empty() && d.upstream_theta.size() == 0) {
      r.note = fmt::format("{} could not be fitted, and {} needs its estimate", up, model->name());
    }
    if (model->name() == "magellipsoid" &&
        (!r.estimate.estimate.ok || r.estimate.estimate.rank < model->num_parameters() ||
         !r.estimate.weak.empty())) {
      const std::string why = !r.estimate.estimate.ok           ? r.estimate.estimate.error
                              : r.estimate.gate_reasons.empty() ? std::string("rank loss")
                                                                : r.estimate.gate_reasons.front();
      auto sphere = MakeFreeModel("magsphere", context, error);
      if (!sphere) return false;
      FreeModelResult s;
      s.requested = "magellipsoid";
      s.model = "magsphere";
      s.estimate = CalibrateFree(*sphere, d, options);
      s.note = fmt::format(
          "the data cannot carry an ellipsoid ({}; coverage {:.1f} % of the sphere): fitted a "
          "sphere (hard iron and one gain) instead",
          why, 100 * s.estimate.coverage.fraction());
      if (s.estimate.estimate.ok && !s.estimate.gate_passed && !s.estimate.gate_reasons.empty()) {
        s.note += "; the sphere is refused too: " + s.estimate.gate_reasons.front();
      }
      out->push_back(std::move(s));
      continue;
    }
    out->push_back(std::move(r));
  }
  return true;
}

std::vector<std::string> DefaultFreeModels(const std::vector<FreeInterval>& intervals) {
  bool acc = false, gyr = false, mag = false, moves = false;
  for (const auto& iv : intervals) {
    acc |= iv.acc.has_value();
    gyr |= iv.gyr.has_value();
    mag |= iv.mag.has_value();
    moves |= iv.move_in.has_value();
  }
  std::vector<std::string> out;
  if (acc) out.push_back("accel9");
  if (acc && gyr && moves) out.push_back("gyro9");
  if (mag) out.push_back("magellipsoid");
  if (acc && mag) out.push_back("accmag");
  return out;
}

double FitErrorPercent(const FreeEstimate& fe, SensorKind model_sensor, SensorKind triad,
                       const FreeContext& context) {
  const bool mag = triad == SensorKind::kMagnetometer;
  // A joint model (accmag) names its magnetometer's norm "mag norm" (its "norm" is gravity's); a
  // model of one triad, "norm".
  const bool joint = mag && std::any_of(fe.after.begin(), fe.after.end(),
                                        [](const MisfitFigure& f) { return f.kind == "mag norm"; });
  if (!joint && triad != model_sensor) return NAN;
  const std::string kind = joint ? "mag norm" : "norm";
  const double magnitude =
      mag ? (fe.relative_scale || !(context.field_magnitude > 0) ? 1.0 : context.field_magnitude)
          : context.gravity_mps2;
  for (const auto& f : fe.after) {
    if (f.kind == kind && f.count > 0) return 100 * f.rms / magnitude;
  }
  return NAN;
}

}  // namespace turncal
