#include "tools/sim_thermal.h"

#include <cmath>

namespace turncal::tools {

bool ApplyChamberArgs(const SimCommandArgs& args, SessionSimOptions* session, std::string* error) {
  const bool chamber_options = args.repeat_poses || args.die_tau_s != DieThermal{}.tau_s ||
                               args.self_heating_c != DieThermal{}.self_heating_c ||
                               args.temp_quantum_c != DieThermal{}.quantum_c ||
                               args.temp_hysteresis_c != DieThermal{}.hysteresis_c;
  if (args.chamber.empty()) {
    if (chamber_options) {
      *error =
          "--repeat-poses, --die-tau, --self-heating, --temp-quantum and --temp-hysteresis need "
          "--chamber";
      return false;
    }
    return true;
  }
  ChamberProfile profile;
  if (!ChamberProfile::Parse(args.chamber, &profile, error)) {
    *error = "--chamber: " + *error;
    return false;
  }
  DieThermal die;
  die.tau_s = args.die_tau_s;
  die.self_heating_c = args.self_heating_c;
  die.quantum_c = args.temp_quantum_c;
  die.hysteresis_c = args.temp_hysteresis_c;
  if (!die.IsValid(error)) return false;
  session->chamber = profile;
  session->die = die;
  session->repeat_poses_through_chamber = args.repeat_poses;
  return true;
}

namespace {

nlohmann::json Triad(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

nlohmann::json ModelTruth(const std::string& name, const ThermalTruth& truth,
                          const Eigen::Vector3d& last_pose_wander) {
  std::string error;
  const auto model = MakeModel(name, ModelContext{}, &error);
  nlohmann::json orders = nlohmann::json::object(), coefficients = nlohmann::json::object();
  Eigen::VectorXd c = truth.coefficients;
  // The biases a calibration reports are the bias over the latest pose's window.
  if (const int b = model->index_of("bx"); b >= 0) {
    for (int axis = 0; axis < 3; ++axis)
      c[truth.basis.index(b + axis, 0)] += last_pose_wander[axis];
  }
  for (int p = 0; p < model->num_parameters(); ++p) {
    orders[model->parameters()[static_cast<std::size_t>(p)].name] = truth.basis.orders[p];
  }
  for (int k = 0; k < truth.basis.num_coefficients(); ++k) {
    coefficients[truth.basis.CoefficientName(model->parameters(), k)] = c[k];
  }
  return {{"t0_c", truth.basis.t0_c}, {"orders", orders}, {"coefficients", coefficients}};
}

}  // namespace

nlohmann::json ThermalTruthJson(const sim::SimCapture& capture) {
  const SimulatedSession& s = capture.session;
  const SessionSimOptions& so = capture.session_options;
  if (!so.chamber) return nullptr;
  nlohmann::json models = nlohmann::json::object();
  const SessionPoseEvent* last = s.events.empty() ? nullptr : &s.events.back();
  if (s.accel_thermal) {
    models[capture.accel_model] =
        ModelTruth(capture.accel_model, *s.accel_thermal,
                   last ? last->acc_wander_mean : Eigen::Vector3d(Eigen::Vector3d::Zero()));
  }
  if (s.mag_thermal) {
    models[capture.mag_model] =
        ModelTruth(capture.mag_model, *s.mag_thermal,
                   last ? last->mag_wander_mean : Eigen::Vector3d(Eigen::Vector3d::Zero()));
  }
  if (s.gyro_thermal && !capture.gyro_model.empty()) {
    models[capture.gyro_model] =
        ModelTruth(capture.gyro_model, *s.gyro_thermal,
                   last ? last->gyr_wander_mean : Eigen::Vector3d(Eigen::Vector3d::Zero()));
  }
  constexpr double kSlice_s = 1.0;
  nlohmann::json poses = nlohmann::json::array();
  for (const SessionPoseEvent& e : s.events) {
    nlohmann::json acc = nlohmann::json::array(), mag = nlohmann::json::array(),
                   gyr = nlohmann::json::array();
    for (double t = e.t_s; t < e.dwell_end_s - 1e-9; t += kSlice_s) {
      const double t1 = std::min(t + kSlice_s, e.dwell_end_s);
      acc.push_back(Triad(s.AccDriftMean(t, t1)));
      mag.push_back(Triad(s.MagDriftMean(t, t1)));
      if (!capture.gyro_model.empty()) gyr.push_back(Triad(s.GyrDriftMean(t, t1)));
    }
    nlohmann::json p = {
        {"index", e.index},
        {"t_s", e.t_s},
        {"dwell_end_s", e.dwell_end_s},
        {"die_mean_c",
         std::isfinite(e.die_mean_c) ? nlohmann::json(e.die_mean_c) : nlohmann::json()},
        {"parameter_mean_c",
         std::isfinite(e.parameter_mean_c) ? nlohmann::json(e.parameter_mean_c) : nlohmann::json()},
        {"wander", {{"acc", acc}, {"mag", mag}}}};
    if (!capture.gyro_model.empty()) p["wander"]["gyr"] = gyr;
    poses.push_back(p);
  }
  return {{"chamber", so.chamber->ToString()},
          {"die",
           {{"tau_s", so.die.tau_s},
            {"self_heating_c", so.die.self_heating_c},
            {"self_heating_tau_s", so.die.self_heating_tau_s},
            {"quantum_c", so.die.quantum_c},
            {"hysteresis_c", so.die.hysteresis_c}}},
          {"bias_truth", "at_last_pose"},
          {"wander_slice_s", kSlice_s},
          {"models", models},
          {"poses", poses}};
}

}  // namespace turncal::tools
