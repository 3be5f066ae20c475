// The pose calibration document's writer and the applied-values reader
// (protocol/calibration_json.h); the full parser is calibration_json.cc.

#include <cmath>

#include "protocol/calibration_json.h"
#include "protocol/observability_json.h"
#include "protocol/pose_json.h"
#include "protocol/sequencer_json.h"
#include "turncal/version.h"

namespace turncal::protocol {

nlohmann::json DriftScaleJson(const Estimate& e) {
  nlohmann::json j = ToJson(e.drift_scale);
  j["used"] = e.drift_scale_used;
  return j;
}

nlohmann::json ParamsJson(const Estimate& e) {
  nlohmann::json params = nlohmann::json::object();
  // A refused solve (too few poses) names its parameters but has no values yet.
  if (e.theta.size() != static_cast<Eigen::Index>(e.parameters.size()) ||
      e.sigma.size() != e.theta.size()) {
    return params;
  }
  for (std::size_t i = 0; i < e.parameters.size(); ++i) {
    const auto k = static_cast<Eigen::Index>(i);
    params[e.parameters[i].name] = {
        {"value", e.theta[k]},
        {"sigma", std::isfinite(e.sigma[k]) ? nlohmann::json(e.sigma[k]) : nlohmann::json()}};
  }
  return params;
}

nlohmann::json CovarianceJson(const Eigen::MatrixXd& covariance) {
  nlohmann::json rows = nlohmann::json::array();
  for (Eigen::Index r = 0; r < covariance.rows(); ++r) {
    nlohmann::json row = nlohmann::json::array();
    for (Eigen::Index c = 0; c < covariance.cols(); ++c) {
      const double v = covariance(r, c);
      row.push_back(std::isfinite(v) ? nlohmann::json(v) : nlohmann::json());
    }
    rows.push_back(row);
  }
  return rows;
}

namespace {

// The poses and records that hold the model's triad (an accelerometer's leave out rate
// segments), each record with that triad only: the document can be re-evaluated (the report's
// residuals and convergence) without the journal, which `reset` archives.
nlohmann::json ProvenanceJson(const PoseCalibrationInput& in) {
  const SensorKind sensor = in.model->sensor();
  const std::size_t n = std::min(in.count, in.poses->size());
  nlohmann::json pose_list = nlohmann::json::array();
  for (std::size_t i = 0; i < n; ++i) {
    if (i < in.records->size() && !TriadFor(sensor, (*in.records)[i])) continue;
    pose_list.push_back(protocol::ToJson((*in.poses)[i]));
  }
  nlohmann::json records = nlohmann::json::array();
  for (std::size_t i = 0; i < n && i < in.records->size(); ++i) {
    PoseRecord r = (*in.records)[i];
    if (!TriadFor(sensor, r)) continue;
    if (sensor != SensorKind::kAccelerometer) r.acc.reset();
    if (sensor != SensorKind::kGyroscope) r.gyr.reset();
    if (sensor != SensorKind::kMagnetometer) r.mag.reset();
    // A gyroscope's moves go with their blocks (the report re-weighs them): ~80 kB a move of
    // 6 s at 10 ms blocks.
    if (sensor != SensorKind::kGyroscope) r.move_in.reset();
    records.push_back(ToJson(r));
  }
  // Device identity and the device-side stored calibration come from the device dialogue of a
  // live station; a replay does not have them (null).
  return {{"poses", pose_list}, {"records", records}, {"device_identity", in.identity}};
}

}  // namespace

nlohmann::json PoseCalibrationJson(const PoseCalibrationInput& in) {
  const Estimate& e = *in.estimate;
  nlohmann::json order = nlohmann::json::array();
  for (const auto& p : e.parameters) order.push_back(p.name);
  nlohmann::json calibrator = CalibratorJson(in.calibrator, in.sensor_class);
  if (e.drift.enabled()) {
    // The drift the solve used (the prior times the identified scale): corrected output's sigma
    // grows with it, also after a restart; the configured one stays as the prior.
    calibrator["drift_prior"] = calibrator["drift"];
    calibrator["drift"] = ToJson(e.drift);
    calibrator["drift_scale"] = DriftScaleJson(e);
  }
  return {{"schema", 1},
          {"class", "CALIBRATION"},
          {"device", in.device},
          {"model", in.model->name()},
          {"version", in.version},
          {"software", kVersion},
          {"params", ParamsJson(e)},
          {"parameter_order", order},
          {"covariance", CovarianceJson(e.covariance)},
          {"gauge", e.gauge},
          {"bias_window", e.bias_window ? ToJson(*e.bias_window) : nlohmann::json()},
          {"rank", in.rank},
          {"chi2", e.chi2},
          {"dof", e.dof},
          {"p_value", e.p_value},
          {"fit_check", ToJson(e.fit, in.model->sensor())},
          {"gate", turncal::ToJson(in.gate)},
          {"tolerances", TolerancesJson(*in.model, in.gate_options)},
          {"context", ToJson(in.context)},
          {"calibrator", calibrator},
          {"provenance", ProvenanceJson(in)}};
}

bool ReadCalibrationValues(const MeasurementModel& model, const nlohmann::json& stored,
                           Eigen::VectorXd* theta, Eigen::MatrixXd* covariance) {
  const auto& params = model.parameters();
  Eigen::VectorXd t(static_cast<Eigen::Index>(params.size()));
  bool ok = stored.is_object() && stored.contains("params") && stored["params"].is_object();
  for (std::size_t i = 0; ok && i < params.size(); ++i) {
    const auto it = stored["params"].find(params[i].name);
    ok = it != stored["params"].end() && it->is_object() && (*it)["value"].is_number();
    if (ok) t[static_cast<Eigen::Index>(i)] = (*it)["value"].get<double>();
  }
  if (!ok) return false;
  *theta = t;
  covariance->resize(0, 0);
  const auto& cov = stored.value("covariance", nlohmann::json());
  if (cov.is_array() && cov.size() == params.size()) {
    Eigen::MatrixXd c(t.size(), t.size());
    bool good = true;
    for (std::size_t r = 0; good && r < params.size(); ++r) {
      good = cov[r].is_array() && cov[r].size() == params.size();
      for (std::size_t k = 0; good && k < params.size(); ++k) {
        good = cov[r][k].is_number();
        if (good) {
          c(static_cast<Eigen::Index>(r), static_cast<Eigen::Index>(k)) = cov[r][k].get<double>();
        }
      }
    }
    if (good) *covariance = c;
  }
  return true;
}

}  // namespace turncal::protocol
