#pragma once
// Maximum-likelihood calibration of one measurement model from pose records (issue "Calibration
// engine"; MODELS.md "Noise, whitening and honest uncertainty").
//
// Each pose contributes the mean of its stationary window; its residual is whitened with the
// covariance of that mean (batch-means estimate when the record has one, else sample covariance
// / n), floored by the configured noise, so the cost is a negative log-likelihood. The start comes
// from the linear form (MODELS.md), then Ceres Levenberg-Marquardt with automatic derivatives
// refines it; later solves warm-start from the previous estimate.

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/estimation/bias_drift.h"
#include "core/estimation/drift_identify.h"
#include "core/estimation/fit_check.h"
#include "core/estimation/move_record.h"
#include "core/estimation/pose_record.h"
#include "core/modeling/measurement_model.h"

namespace ceres {
class CostFunction;
class LossFunction;
}  // namespace ceres

namespace turncal {

enum class RobustLoss { kNone, kHuber, kCauchy };

// How mag22's two unobservable directions (MODELS.md "The mag22 gauge") are fixed.
enum class Mag22Gauge {
  // det K_ = 1 and dB orthogonal to R3(beta) B_NED: dB is the platform field's part that cannot
  // be mistaken for a gain change of the sensor.
  kUnitDetKOrthogonalDeltaB,
};

const char* ToString(RobustLoss loss);
const char* ToString(Mag22Gauge gauge);

struct CalibratorOptions {
  std::string model = "accel13";
  ModelContext context;

  // Robust loss on each pose's squared whitened residual norm s: Huber is quadratic for
  // sqrt(s) <= loss_scale. 4 keeps clean data (chi^2 with 3 dof exceeds 16 with probability
  // 0.1%) at full efficiency while a pose off by tens of sigma loses its pull.
  RobustLoss loss = RobustLoss::kHuber;
  double loss_scale = 4.0;

  // The covariance of a pose mean is the record's estimate (batch means, or sample covariance /
  // n), its eigenvalues floored at WhiteFloorFraction(n) x noise_density^2 / (2 duration) --
  // white noise of one-sided density N (triad unit per sqrt(Hz)) averaged over T seconds, a
  // level a white window's own estimate falls below only by accident -- plus pose_offset_sigma^2 on
  // each axis for what averaging cannot remove and one window cannot see: bias instability
  // between poses (~4e-4 m/s^2 for an industrial MEMS accelerometer, SENSORS.md).
  double noise_density = 0.0;
  double pose_offset_sigma = 0.0;
  // A rate segment's rate is the table's to this relative 1 sigma (averaged over its whole
  // revolutions; a rate table's datasheet "rate accuracy"): its variance along the turning axis,
  // in the gyro's nominal frame, is added to the record's covariance. 1e-5 by default
  // ([table] rate_accuracy).
  double rate_accuracy = 1e-5;

  // Bias drift as a process in time (core/estimation/bias_drift.h). When enabled, the poses' errors
  // are correlated through it and the calibrator solves by generalised least squares over all poses
  // (core/estimation/gls_whitening.h); the bias parameters are then the bias over the latest pose's
  // window (Estimate::bias_window). Every record needs its time window. pose_offset_sigma, if also
  // set, stays an independent per-pose offset (e.g. the table's repositioning).
  BiasDrift drift;
  // Identify the drift's strength from the poses (core/estimation/drift_identify.h): `drift` is
  // then the prior, and once the poses reject it the solve uses their own estimate of a scale on it
  // (re-solving when the scale in use moves by more than 5 %). Needs a drift model and a model
  // without a gauge.
  bool identify_drift = false;
  DriftScaleOptions drift_scale;

  int max_iterations = 100;
  double function_tolerance = 1e-12;
  double gradient_tolerance = 1e-14;
  double parameter_tolerance = 1e-12;

  // When chi^2 exceeds its degrees of freedom with p-value below this, the covariance is
  // inflated by chi^2/dof and the estimate says so (a model that does not fit, or drift). The
  // same level is the two-sided fit check's per tail (Estimate::fit): chi^2 far below its
  // degrees of freedom is reported too, with its likely cause, but does not shrink the
  // covariance (docs/ACCURACY.md "The fit check").
  bool inflate_covariance_by_chi2 = true;
  double chi2_inflation_p_value = 0.01;

  // A pose whose normalised residual sqrt(r^T r / 3) exceeds this is flagged as an outlier.
  double outlier_threshold = 4.0;

  // Singular values of the column-scaled whitened Jacobian below this fraction of the largest
  // count as rank loss.
  double rank_tolerance = 1e-9;

  // Re-run the linear start when a warm-started solve ends with a cost per degree of freedom
  // this many times the previous one, or fails.
  double restart_cost_ratio = 25.0;

  Mag22Gauge mag22_gauge = Mag22Gauge::kUnitDetKOrthogonalDeltaB;

  bool IsValid(std::string* error) const;
};

struct PoseResidual {
  Eigen::Vector3d raw = Eigen::Vector3d::Zero();       // measured mean - prediction, triad unit
  Eigen::Vector3d whitened = Eigen::Vector3d::Zero();  // Sigma^{-1/2} raw
  double normalized = 0.0;                             // sqrt(whitened^T whitened / 3)
  bool outlier = false;
};

struct Estimate {
  bool ok = false;    // a solution exists (it may still be flagged, see warnings)
  std::string error;  // why not, when !ok
  std::string model;
  std::vector<ParameterInfo> parameters;
  Eigen::VectorXd theta;
  Eigen::MatrixXd covariance;  // in the parameters' order; in the gauge for mag22
  Eigen::VectorXd sigma;       // sqrt of the covariance's diagonal; inf when undetermined
  int rank = 0;                // of the whitened Jacobian, out of parameters.size()
  double condition = 0.0;      // of the column-scaled whitened Jacobian
  int poses = 0;               // pose records (static poses and rate segments)
  int moves = 0;  // moves between poses (a gyroscope's; residuals has poses + moves entries)
  std::vector<PoseResidual> residuals;
  double chi2 = 0.0;
  int dof = 0;
  double p_value = 1.0;
  double covariance_scale = 1.0;  // > 1 when inflated by chi^2/dof
  FitCheck fit;                   // the two-sided chi^2 check with its likely cause
  std::string gauge;              // mag22: the gauge applied; empty otherwise
  // With a drift model: the time window the bias parameters hold for (the latest pose's) and
  // the drift model, so a user of the estimate can grow the bias sigma with time since.
  std::optional<TimeWindow> bias_window;
  BiasDrift drift;         // the drift model the solve used (the prior times drift_scale_used)
  DriftScale drift_scale;  // identified from the poses (CalibratorOptions::identify_drift)
  double drift_scale_used = 1.0;  // 1 until the poses reject the prior, then its use_scale
  bool linear_start = false;      // this solve started from the linear form
  int iterations = 0;
  std::string termination;
  double solve_time_s = 0.0;  // Ceres' own measurement of the solve
  std::vector<std::string> warnings;

  // The value and 1 sigma of a parameter by name (NaN when unknown).
  double value(std::string_view name) const;
  double sigma_of(std::string_view name) const;
  std::string BriefReport() const;
  std::string FullReport() const;
};

// The floor on a pose's white covariance, as a fraction of the configured density's level, for
// a window of `count` samples (0: unknown, as for batch means). The smallest eigenvalue of a 3x3
// sample covariance of n white samples falls below 1 - 4 sqrt(2/n) of the truth in under 0.1 %
// of windows (0.70 at the 0.1 % quantile for n = 300 against the floor's 0.67; 0.52 and 0.43
// for n = 100), so the floor guards against what cannot be the window's white noise (a stuck or
// flat-quantised channel) without lifting honest low draws: a floor at the level itself keeps
// every high draw and lifts every low one, +4.8 % on the variance at n = 300 (sigma too large,
// chi^2 too small). Never below 0.1.
double WhiteFloorFraction(std::int64_t count);

// The record's statistics of the triad a model of `sensor` calibrates (nullptr when it has none,
// e.g. a rate segment's record for an accelerometer).
const TriadStats* TriadFor(SensorKind sensor, const PoseRecord& record);

class Calibrator {
 public:
  // Options must be valid (check IsValid first); an invalid model yields estimates with !ok.
  explicit Calibrator(CalibratorOptions options);
  ~Calibrator();
  Calibrator(const Calibrator&) = delete;
  Calibrator& operator=(const Calibrator&) = delete;

  // Adds a pose. False with a message (and nothing added) when the record lacks the model's
  // triad, holds a non-finite value, or has a covariance that is singular with no floor set.
  // A gyroscope model also adds the move that led to the pose (PoseRecord::move_in, add_move);
  // a move it cannot use is left out and counted (moves_refused), the pose kept.
  bool add_pose(const PoseRecord& record, std::string* error);

  // Adds a move between two static poses (a gyroscope model only; core/estimation/move_residual.h),
  // weighed by the gyro's white noise (noise_density) over its blocks, the pose-to-pose offset,
  // and with a drift model correlated with the poses through the bias process over its window.
  // False with a message (nothing added) for another model or an invalid record.
  bool add_move(const MoveRecord& move, std::string* error);

  // Estimates the parameters from every pose added so far.
  Estimate solve();

  // Residual blocks: the poses and the moves added so far.
  int num_poses() const;
  int num_moves() const { return moves_; }
  int moves_refused() const { return moves_refused_; }
  const std::string& last_move_refusal() const { return last_move_refusal_; }
  // The poses added so far with the weights the estimator gives them (for the observability
  // analysis and the pose planner).
  std::vector<WeightedPose> weighted_poses() const;
  // The poses weighed by their own white noise only, and their windows on the sensor's clock
  // (empty without a drift model): what the pose planner needs to place a new pose in time.
  void planning_poses(std::vector<WeightedPose>* white, std::vector<TimeWindow>* windows) const;
  const MeasurementModel* model() const { return model_.get(); }
  const CalibratorOptions& options() const { return options_; }

 private:
  struct Pose;
  // One solve from the poses as they are, in steps: PrepareSolve, Minimize, Canonicalize,
  // RankAndCovariance, ComputeResiduals, CheckFitAndInflate, MarkUndetermined.
  Estimate SolveOnce();
  // The estimate's model, counts and parameters, and the residual blocks; false (est->error
  // says why) without a model, with too few poses or when the blocks cannot be built.
  bool PrepareSolve(Estimate* est);
  // Solves warm from the last estimate, or from the linear form (nominal values without one)
  // when there is none or the warm solve ends far worse; false when the solver fails.
  bool Minimize(Eigen::VectorXd* theta, Estimate* est) const;
  // The estimate on its canonical branch: beta in (-pi, pi], the physical parameters as the LQ
  // decomposition of their G gives them, mag22's gauge applied.
  void Canonicalize(Eigen::VectorXd* theta_out, Estimate* est) const;
  // Rank and condition of the Jacobian the solver sees at theta, and the covariance.
  Eigen::MatrixXd RankAndCovariance(Eigen::VectorXd* theta, Estimate* est) const;
  // mag22's covariance: the inverse Fisher information in the gauge's tangent space.
  Eigen::MatrixXd GaugeCovariance(const Eigen::MatrixXd& J, const Eigen::VectorXd& theta) const;
  // Each pose's residual (with drift: its innovation), chi^2, dof and p-value.
  void ComputeResiduals(const Eigen::VectorXd& theta, Estimate* est) const;
  // The two-sided fit check, the outliers, the covariance inflated when chi^2 is too large.
  void CheckFitAndInflate(Estimate* est, Eigen::MatrixXd* cov) const;
  // Sigma infinite for the parameters the poses do not determine (rank below identifiable).
  void MarkUndetermined(const Eigen::VectorXd& theta, Estimate* est) const;
  // The drift scale the poses and `est` (a solve) give, with options_.drift as the prior.
  DriftScale IdentifyDrift(const Estimate& est) const;
  bool StartFromLinearForm(Eigen::VectorXd* theta, std::string* error) const;
  // A record's measured - predicted at theta, with d(predicted)/d(theta) when asked (a move:
  // its residual s, core/estimation/move_residual.h).
  Eigen::Vector3d MeasuredMinusPredicted(const Pose& p, const Eigen::VectorXd& theta,
                                         Jacobian3* jacobian) const;
  bool StartGyro(const std::vector<TablePose>& poses, const std::vector<Eigen::Vector3d>& measured,
                 Eigen::VectorXd* theta, std::string* error) const;

  // The residual blocks the solver sees: each pose's own (no drift), or each pose's whitened
  // innovation (drift; rebuilt for every solve, order_ gives the poses' time order).
  bool BuildBlocks(std::string* error);
  // With a drift model: each pose's white covariance as the generalised least squares weighs it,
  // its own plus SampleWeightCorrection with its block of the inverse of the poses' joint
  // covariance under `drift` (core/estimation/pose_record.h; the block's diagonal, axis by axis).
  // The poses' own when that covariance cannot be factored (BuildGlsWhitening then says why).
  std::vector<Eigen::Matrix3d> WeighedWhites(const BiasDrift& drift) const;
  int moves_ = 0, moves_refused_ = 0;
  std::string last_move_refusal_;
  std::vector<ceres::CostFunction*> blocks_;
  std::vector<std::unique_ptr<ceres::CostFunction>> gls_blocks_;
  Eigen::MatrixXd gls_w_;
  // The whites the last BuildBlocks weighed with (WeighedWhites at drift_): IdentifyDrift's,
  // right after the solve that built them.
  std::vector<Eigen::Matrix3d> gls_white_;
  std::vector<int> order_;

  CalibratorOptions options_;
  std::unique_ptr<MeasurementModel> model_;
  std::string model_error_;
  std::unique_ptr<ceres::LossFunction> loss_;
  std::vector<Pose> poses_;
  Eigen::VectorXd theta_;  // last estimate, for warm starts
  // The drift model in use: options_.drift times the identified scale.
  BiasDrift drift_;
  double drift_scale_ = 1.0;
  double last_cost_per_dof_ = 0.0;
};

}  // namespace turncal
