#include "montecarlo/calibrator_montecarlo.h"

#include <algorithm>
#include <cmath>
#include <memory>

#include "core/estimation/calibrator.h"
#include "core/estimation/sensor_class.h"
#include "core/planning/pose_designs.h"
#include "montecarlo/ks_uniform.h"
#include "sim/session_sim.h"
#include "sim/synthetic.h"

namespace turncal::montecarlo {
namespace {

// The engine: Run draws the design once, then each run SimulateWhite or SimulateSession into a
// calibrator, Solve, Accumulate; Summarise.
class CalibratorMonteCarlo {
 public:
  explicit CalibratorMonteCarlo(const CalibratorMonteCarloOptions& options) : o_(options) {}

  CalibratorMonteCarloSummary Run() {
    CalibratorMonteCarloSummary s;
    if (!Prepare(&s)) return s;
    const int n = model_->num_parameters();
    sum_sq_err_ = sum_var_ = Eigen::VectorXd::Zero(n);
    s.z = ZScoreSummary(n);
    for (int run = 0; run < o_.runs; ++run) RunOne(run, &s);
    Summarise(&s);
    return s;
  }

 private:
  // The model, the class and the pose design every run shares (one design: the Cramer-Rao bound
  // depends on it).
  bool Prepare(CalibratorMonteCarloSummary* s) {
    model_ = MakeModel(o_.model, ModelContext{}, &s->error);
    if (!model_) return false;
    if (!SensorClassByName(o_.sensor_class, &sensor_)) {
      s->error = "unknown class '" + o_.sensor_class + "'";
      return false;
    }
    s->sensor_class = sensor_.name;
    for (const auto& p : model_->parameters()) s->parameters.push_back(p.name);
    std::mt19937_64 design_rng(o_.seed);
    poses_ = DesignPoses(o_.design, o_.poses, &design_rng);
    if (o_.shuffle) std::shuffle(poses_.begin(), poses_.end(), design_rng);
    s->poses = static_cast<int>(poses_.size());
    accel_ = model_->sensor() == SensorKind::kAccelerometer;
    // For --noise session the other sensor's model only feeds the simulator.
    std::string error;
    other_ = MakeModel(accel_ ? "mag13" : "accel13", ModelContext{}, &error);
    return true;
  }

  // One session: new truth and noise from the run's seed, calibrated.
  void RunOne(int run, CalibratorMonteCarloSummary* s) {
    const std::uint64_t seed = o_.seed * 1000003 + static_cast<std::uint64_t>(run);
    const bool drift = o_.noise == "session" && o_.drift_model == "gauss-markov";
    Calibrator calibrator(drift ? DriftOptionsForClass(*model_, sensor_)
                                : OptionsForClass(*model_, sensor_));
    const Eigen::VectorXd truth = o_.noise == "session"
                                      ? SimulateSessionInto(seed, drift, &calibrator)
                                      : SimulateWhiteInto(seed, &calibrator);
    const Estimate e = calibrator.solve();
    if (!e.ok) {
      ++s->failed;
      return;
    }
    ++s->solved;
    s->p_values.push_back(e.p_value);
    solve_s_ += e.solve_time_s;
    const Eigen::VectorXd err = e.theta - truth;
    sum_sq_err_ += err.cwiseAbs2();
    sum_var_ += e.sigma.cwiseAbs2();
    s->z.Add(err.cwiseQuotient(e.sigma));
  }

  // Pose means with white noise and independent pose offsets around truth drawn from the class;
  // the truth.
  Eigen::VectorXd SimulateWhiteInto(std::uint64_t seed, Calibrator* calibrator) const {
    std::mt19937_64 rng(seed);
    const Eigen::VectorXd truth = DrawTruth(*model_, sensor_, &rng);
    std::string error;
    for (const auto& pose : poses_) {
      calibrator->add_pose(SimulateRecord(*model_, truth, pose, sensor_, o_.dwell_s, &rng), &error);
    }
    return truth;
  }

  // The simulator's full noise model: Gauss-Markov bias wander sampled at the output rate,
  // quantisation, settling; dwell windows cut at the known times. The truth: the bias the
  // calibration estimates, over the last pose with the drift model, averaged over the dwells
  // with independent offsets.
  Eigen::VectorXd SimulateSessionInto(std::uint64_t seed, bool drift,
                                      Calibrator* calibrator) const {
    SessionSimOptions o;
    o.sensor = sensor_;
    o.rate_hz = o_.rate_hz;
    o.dwell_s = o_.dwell_s;
    o.seed = seed;
    const SimulatedSession session = accel_ ? SimulateSession(*model_, *other_, poses_, o)
                                            : SimulateSession(*other_, *model_, poses_, o);
    Eigen::VectorXd truth = accel_ ? session.accel_truth : session.mag_truth;
    if (drift) {
      truth.tail<3>() += accel_ ? session.LastPoseAccBiasOffset() : session.LastPoseMagBiasOffset();
    } else {
      truth.tail<3>() +=
          accel_ ? session.EffectiveAccBiasOffset() : session.EffectiveMagBiasOffset();
    }
    std::string error;
    for (const auto& e : session.events) {
      calibrator->add_pose(DwellRecord(session, e, model_->sensor()), &error);
    }
    return truth;
  }

  void Summarise(CalibratorMonteCarloSummary* s) const {
    const int ok = s->solved;
    s->mean_solve_ms = ok ? 1e3 * solve_s_ / ok : 0.0;
    s->rmse = (sum_sq_err_ / ok).cwiseSqrt();
    s->sigma = (sum_var_ / ok).cwiseSqrt();
    if (s->p_values.size() >= 2) s->ks = KsUniform(s->p_values);
  }

  const CalibratorMonteCarloOptions& o_;
  std::unique_ptr<MeasurementModel> model_, other_;
  SensorClass sensor_;
  bool accel_ = false;
  std::vector<TablePose> poses_;
  Eigen::VectorXd sum_sq_err_, sum_var_;
  double solve_s_ = 0.0;
};

}  // namespace

std::vector<TablePose> DesignPoses(const std::string& design, int count, std::mt19937_64* rng) {
  if (design == "random") return RandomPoses(count, rng);
  if (design == "about-z") return AboutZPoses(count);
  const auto cube = CubePoses26();
  std::vector<TablePose> poses;
  for (int i = 0; i < count; ++i) {
    TablePose p = cube[i % cube.size()];
    const int repeat = i / static_cast<int>(cube.size());
    p.psi_rad += repeat * M_PI / 4;  // repeats turn by 45 deg
    poses.push_back(p);
  }
  return poses;
}

bool CalibratorMonteCarloSummary::Honest(int parameter) const {
  const double std_z = z.Std()[parameter];
  return rmse[parameter] <= 1.1 * sigma[parameter] && std_z >= 0.9 && std_z <= 1.1;
}

bool CalibratorMonteCarloSummary::Passed() const {
  for (int i = 0; i < static_cast<int>(parameters.size()); ++i) {
    if (!Honest(i)) return false;
  }
  return failed == 0;
}

CalibratorMonteCarloSummary RunCalibratorMonteCarlo(const CalibratorMonteCarloOptions& options) {
  return CalibratorMonteCarlo(options).Run();
}

}  // namespace turncal::montecarlo
