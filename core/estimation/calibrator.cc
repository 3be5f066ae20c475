#include "core/estimation/calibrator.h"

#include <ceres/ceres.h>
#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <boost/math/special_functions/gamma.hpp>
#include <cmath>

#include "core/analysis/observability.h"
#include "core/estimation/calibrator_pose.h"
#include "core/estimation/gls_whitening.h"
#include "core/estimation/gyro_linear_start.h"
#include "core/estimation/linear_start.h"
#include "core/estimation/move_residual.h"
#include "core/estimation/scaled_svd.h"
#include "core/modeling/accel_physical.h"
#include "core/modeling/mag22_gauge.h"

namespace turncal {

const char* ToString(RobustLoss loss) {
  switch (loss) {
    case RobustLoss::kNone:
      return "none";
    case RobustLoss::kHuber:
      return "huber";
    case RobustLoss::kCauchy:
      return "cauchy";
  }
  return "?";
}

const char* ToString(Mag22Gauge gauge) {
  switch (gauge) {
    case Mag22Gauge::kUnitDetKOrthogonalDeltaB:
      return "det(K_) = 1, dB orthogonal to R3(beta) B_NED";
  }
  return "?";
}

bool CalibratorOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& message) {
    if (error) *error = message;
    return false;
  };
  const auto names = ModelNames();
  if (std::find(names.begin(), names.end(), model) == names.end()) {
    return fail("unknown model '" + model + "'");
  }
  if (!context.IsValid(error)) return false;
  if (loss != RobustLoss::kNone && !(loss_scale > 0)) return fail("loss_scale must be > 0");
  if (!(rate_accuracy >= 0 && rate_accuracy < 0.1))
    return fail("rate_accuracy must be in [0, 0.1)");
  if (!(noise_density >= 0) || !(pose_offset_sigma >= 0)) {
    return fail("noise_density and pose_offset_sigma must be >= 0");
  }
  if (!drift.IsValid(error)) return false;
  if (max_iterations < 1) return fail("max_iterations must be >= 1");
  if (!(rank_tolerance > 0 && rank_tolerance < 1)) return fail("rank_tolerance must be in (0, 1)");
  if (!(outlier_threshold > 0)) return fail("outlier_threshold must be > 0");
  if (!(chi2_inflation_p_value > 0 && chi2_inflation_p_value < 1)) {
    return fail("chi2_inflation_p_value must be in (0, 1)");
  }
  return true;
}

double Estimate::value(std::string_view name) const {
  for (std::size_t i = 0; i < parameters.size(); ++i)
    if (parameters[i].name == name) return theta[static_cast<Eigen::Index>(i)];
  return std::nan("");
}

double Estimate::sigma_of(std::string_view name) const {
  for (std::size_t i = 0; i < parameters.size(); ++i)
    if (parameters[i].name == name) return sigma[static_cast<Eigen::Index>(i)];
  return std::nan("");
}

std::string Estimate::BriefReport() const {
  if (!ok) return fmt::format("{}: no estimate: {}", model, error);
  return fmt::format(
      "{}: {} poses{}, rank {}/{}, chi2 {:.1f} on {} dof (p = {:.3g}){}{}, {} iterations, {}",
      model, poses, moves > 0 ? fmt::format(" and {} moves", moves) : "", rank, parameters.size(),
      chi2, dof, p_value,
      covariance_scale > 1 ? fmt::format(", covariance x{:.2f}", covariance_scale) : "",
      gauge.empty() ? "" : ", gauge: " + gauge, iterations, termination);
}

std::string Estimate::FullReport() const {
  std::string out = BriefReport() + "\n";
  if (!ok) return out;
  for (std::size_t i = 0; i < parameters.size(); ++i) {
    const auto k = static_cast<Eigen::Index>(i);
    out += fmt::format("  {:<8} {:>+16.9g} +- {:<12.4g} [{}]\n", parameters[i].name, theta[k],
                       sigma[k], ToString(parameters[i].unit));
  }
  for (std::size_t i = 0; i < residuals.size(); ++i) {
    if (residuals[i].outlier) {
      out += fmt::format("  pose {} is an outlier: normalised residual {:.1f}\n", i,
                         residuals[i].normalized);
    }
  }
  for (const auto& w : warnings) out += "  warning: " + w + "\n";
  return out;
}

namespace {

std::unique_ptr<ceres::LossFunction> MakeLoss(RobustLoss loss, double scale) {
  switch (loss) {
    case RobustLoss::kNone:
      return nullptr;
    case RobustLoss::kHuber:
      return std::make_unique<ceres::HuberLoss>(scale);
    case RobustLoss::kCauchy:
      return std::make_unique<ceres::CauchyLoss>(scale);
  }
  return nullptr;
}

}  // namespace

namespace {

// Dense Jacobian of all residuals (with the robust loss's reweighting, as the solver sees it).
Eigen::MatrixXd DenseJacobian(ceres::Problem* problem) {
  ceres::CRSMatrix crs;
  problem->Evaluate(ceres::Problem::EvaluateOptions(), nullptr, nullptr, nullptr, &crs);
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(crs.num_rows, crs.num_cols);
  for (int r = 0; r < crs.num_rows; ++r)
    for (int k = crs.rows[r]; k < crs.rows[r + 1]; ++k) J(r, crs.cols[k]) = crs.values[k];
  return J;
}

}  // namespace

Calibrator::Calibrator(CalibratorOptions options)
    : options_(std::move(options)), drift_(options_.drift) {
  if (options_.IsValid(&model_error_)) {
    model_ = MakeModel(options_.model, options_.context, &model_error_);
  }
  loss_ = MakeLoss(options_.loss, options_.loss_scale);
}

Calibrator::~Calibrator() = default;

int Calibrator::num_poses() const { return static_cast<int>(poses_.size()); }

bool Calibrator::StartFromLinearForm(Eigen::VectorXd* theta, std::string* error) const {
  std::vector<TablePose> poses;
  std::vector<Eigen::Vector3d> measured;
  for (const auto& p : poses_) {
    if (p.move) continue;  // the linear start uses the poses' means only
    poses.push_back(p.weighted.pose);
    measured.push_back(p.weighted.measured);
  }
  if (model_->sensor() == SensorKind::kGyroscope) return StartGyro(poses, measured, theta, error);
  LinearStart start;
  if (!SolveLinearStart(poses, measured, model_->excitation_ned(), &start, error)) return false;
  return model_->FromLinear(start.G, start.beta, start.b, theta, error);
}

bool Calibrator::StartGyro(const std::vector<TablePose>& poses,
                           const std::vector<Eigen::Vector3d>& measured, Eigen::VectorXd* theta,
                           std::string* error) const {
  const Eigen::Vector3d f_ned = SpecificForceNed(options_.context.reference);
  std::vector<Eigen::Vector3d> omega_q, f_q;
  for (const auto& pose : poses) {
    const Mat3<double> C = pose.MeanC_p_q();
    omega_q.push_back(C * model_->excitation_ned() + pose.TableRate_q());
    f_q.push_back(C * f_ned);
  }
  const int first_g = model_->index_of("Bg_xx");
  GyroLinearStart start;
  if (!SolveGyroLinearStart(omega_q, f_q, measured, first_g >= 0, options_.context.mounting, &start,
                            error)) {
    return false;
  }
  if (!model_->FromLinear(start.G, 0.0, start.b, theta, error)) return false;
  if (first_g >= 0) {
    for (int k = 0; k < 9; ++k) (*theta)[first_g + k] = start.B(k / 3, k % 3);
  }
  return true;
}

bool Calibrator::BuildBlocks(std::string* error) {
  blocks_.clear();
  gls_blocks_.clear();
  order_.clear();
  if (!options_.drift.enabled()) {
    for (auto& p : poses_) blocks_.push_back(p.cost.get());
    return true;
  }
  std::vector<TimeWindow> windows;
  for (const auto& p : poses_) windows.push_back(p.window);
  gls_white_ = WeighedWhites(drift_);
  GlsWhitening gls;
  if (!BuildGlsWhitening(windows, gls_white_, drift_, &gls, error)) return false;
  order_ = gls.order;
  gls_w_ = gls.W;
  const int n = num_poses();
  std::vector<const ceres::CostFunction*> raw;
  for (const auto& p : poses_) raw.push_back(p.raw.get());
  auto cache = std::make_shared<RawResidualCache>(std::move(raw), model_->num_parameters());
  for (int k = 0; k < n; ++k) {
    auto cost = std::make_unique<InnovationCost>(cache, model_->num_parameters());
    for (int j = 0; j <= k; ++j) {
      const Eigen::Matrix3d weight = gls.W.block<3, 3>(3 * k, 3 * j);
      if (weight.isZero(0.0)) continue;
      cost->Add(gls.order[j], weight);
    }
    blocks_.push_back(cost.get());
    gls_blocks_.push_back(std::move(cost));
  }
  return true;
}

std::vector<Eigen::Matrix3d> Calibrator::WeighedWhites(const BiasDrift& drift) const {
  std::vector<Eigen::Matrix3d> white;
  std::vector<TimeWindow> windows;
  bool sampled = false;
  for (const auto& p : poses_) {
    white.push_back(p.white);
    windows.push_back(p.window);
    sampled = sampled || p.white_dof > 4.0;
  }
  if (!sampled || !drift.enabled()) return white;
  // Each pose's block of C^-1, axis by axis: the drift is independent per axis, and a second-
  // order correction does not need the whites' small cross-axis terms. Three n x n inverses
  // cost a ninth of the joint 3n x 3n one the solve builds (BuildGlsWhitening).
  const auto n = static_cast<Eigen::Index>(poses_.size());
  const int ref = TimeOrder(windows).back();
  Eigen::MatrixXd precision_diagonal(n, 3);
  for (int axis = 0; axis < 3; ++axis) {
    Eigen::MatrixXd C = DriftIncrementCovariance(drift, axis, windows, ref);
    for (Eigen::Index i = 0; i < n; ++i) C(i, i) += white[static_cast<std::size_t>(i)](axis, axis);
    const Eigen::LLT<Eigen::MatrixXd> llt(C);
    if (llt.info() != Eigen::Success) return white;  // the solve's own build says why
    const Eigen::MatrixXd l_inv = llt.matrixL().solve(Eigen::MatrixXd::Identity(n, n));
    // diag(C^-1) = the squared column norms of L^-1.
    precision_diagonal.col(axis) = l_inv.colwise().squaredNorm().transpose();
  }
  if (!precision_diagonal.allFinite()) return white;
  for (Eigen::Index i = 0; i < n; ++i) {
    const Pose& p = poses_[static_cast<std::size_t>(i)];
    if (!(p.white_dof > 4.0)) continue;
    const Eigen::Matrix3d precision = precision_diagonal.row(i).transpose().asDiagonal();
    white[static_cast<std::size_t>(i)] +=
        SampleWeightCorrection(p.white_sample, precision, p.white_dof);
  }
  return white;
}

Estimate Calibrator::solve() {
  Estimate est = SolveOnce();
  if (!options_.identify_drift || !options_.drift.enabled() || !est.ok || !model_ ||
      model_->gauge_dimension() > 0) {
    return est;
  }
  const DriftScale scale = IdentifyDrift(est);
  if (!scale.identified) return est;
  // The configured drift until the poses reject it; then theirs.
  const double use = scale.use_scale;
  if (std::abs(std::log(use / drift_scale_)) > 0.05) {
    drift_scale_ = use;
    drift_ = ScaledDrift(options_.drift, drift_scale_);
    est = SolveOnce();
  }
  est.drift_scale = scale;
  est.drift_scale_used = drift_scale_;
  return est;
}

DriftScale Calibrator::IdentifyDrift(const Estimate& est) const {
  const int n = num_poses(), N = model_->num_parameters();
  Eigen::MatrixXd J(3 * n, N);
  Eigen::VectorXd r(3 * n);
  std::vector<Eigen::Vector3d> white;
  std::vector<TimeWindow> windows;
  Jacobian3 Ji;
  for (int i = 0; i < n; ++i) {
    const Pose& p = poses_[static_cast<std::size_t>(i)];
    MeasuredMinusPredicted(p, est.theta, &Ji);
    J.middleRows<3>(3 * i) = Ji;
    r.segment<3>(3 * i) = est.residuals[static_cast<std::size_t>(i)].raw;
    white.push_back(gls_white_[static_cast<std::size_t>(i)].diagonal());
    windows.push_back(p.window);
  }
  return IdentifyDriftScale(J, r, white, windows, options_.drift, options_.drift_scale);
}

namespace {

// The solver's problem does not own the blocks or the loss: the calibrator keeps them.
ceres::Problem::Options ProblemOptions() {
  ceres::Problem::Options problem_options;
  problem_options.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  return problem_options;
}

ceres::Solver::Options SolverOptions(const CalibratorOptions& options) {
  ceres::Solver::Options solver_options;
  solver_options.minimizer_type = ceres::TRUST_REGION;
  solver_options.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  solver_options.linear_solver_type = ceres::DENSE_QR;
  solver_options.max_num_iterations = options.max_iterations;
  solver_options.function_tolerance = options.function_tolerance;
  solver_options.gradient_tolerance = options.gradient_tolerance;
  solver_options.parameter_tolerance = options.parameter_tolerance;
  solver_options.logging_type = ceres::SILENT;
  solver_options.num_threads = 1;
  return solver_options;
}

// One solve of `blocks` over theta from where it stands.
void RunSolver(const std::vector<ceres::CostFunction*>& blocks, ceres::LossFunction* loss,
               const CalibratorOptions& options, Eigen::VectorXd* theta,
               ceres::Solver::Summary* summary) {
  ceres::Problem problem(ProblemOptions());
  for (auto* block : blocks) problem.AddResidualBlock(block, loss, theta->data());
  ceres::Solve(SolverOptions(options), &problem, summary);
}

}  // namespace

Estimate Calibrator::SolveOnce() {
  Estimate est;
  if (!PrepareSolve(&est)) return est;
  Eigen::VectorXd theta;
  if (!Minimize(&theta, &est)) {
    theta_.resize(0);
    return est;
  }
  Canonicalize(&theta, &est);
  Eigen::MatrixXd cov = RankAndCovariance(&theta, &est);
  ComputeResiduals(theta, &est);
  CheckFitAndInflate(&est, &cov);
  est.theta = theta;
  est.covariance = cov;
  est.sigma = cov.diagonal().cwiseMax(0.0).cwiseSqrt();
  MarkUndetermined(theta, &est);
  est.ok = true;
  theta_ = theta;
  last_cost_per_dof_ = est.dof > 0 ? est.chi2 / est.dof : 0.0;
  return est;
}

bool Calibrator::PrepareSolve(Estimate* est) {
  est->model = options_.model;
  est->poses = num_poses() - moves_;
  est->moves = moves_;
  if (!model_) {
    est->error = model_error_;
    return false;
  }
  est->parameters = model_->parameters();
  const int n = num_poses();
  const int identifiable = model_->num_parameters() - model_->gauge_dimension();
  if (3 * n < identifiable) {
    est->error = fmt::format("{} poses give {} equations for {} parameters: add at least {} poses",
                             n, 3 * n, identifiable, (identifiable + 2) / 3 - n);
    return false;
  }
  std::string error;
  if (!BuildBlocks(&error)) {
    est->error = error;
    return false;
  }
  return true;
}

bool Calibrator::Minimize(Eigen::VectorXd* theta, Estimate* est) const {
  const int n = num_poses();
  const int identifiable = model_->num_parameters() - model_->gauge_dimension();
  ceres::Solver::Summary summary;
  bool warm = theta_.size() == model_->num_parameters();
  if (warm) {
    *theta = theta_;
    RunSolver(blocks_, loss_.get(), options_, theta, &summary);
    const double cost_per_dof = 2 * summary.final_cost / std::max(1, 3 * n - identifiable);
    if (!summary.IsSolutionUsable() || !theta->allFinite() ||
        cost_per_dof > options_.restart_cost_ratio * std::max(last_cost_per_dof_, 1.0)) {
      est->warnings.push_back(fmt::format(
          "the warm-started solve ended at cost/dof {:.3g} (was {:.3g}); restarted from the "
          "linear form",
          cost_per_dof, last_cost_per_dof_));
      warm = false;
    }
  }
  if (!warm) {
    std::string error;
    if (StartFromLinearForm(theta, &error)) {
      est->linear_start = true;
    } else {
      est->warnings.push_back("no linear start (" + error + "); started from nominal values");
      *theta = model_->nominal();
    }
    RunSolver(blocks_, loss_.get(), options_, theta, &summary);
  }
  est->iterations = static_cast<int>(summary.iterations.size());
  est->termination = ceres::TerminationTypeToString(summary.termination_type);
  est->solve_time_s = summary.total_time_in_seconds;
  if (!summary.IsSolutionUsable() || !theta->allFinite()) {
    est->error = "the solver failed: " + summary.message;
    return false;
  }
  if (summary.termination_type == ceres::NO_CONVERGENCE) {
    est->warnings.push_back(
        fmt::format("the solver stopped after {} iterations without converging", est->iterations));
  }
  return true;
}

void Calibrator::Canonicalize(Eigen::VectorXd* theta_out, Estimate* est) const {
  Eigen::VectorXd& theta = *theta_out;
  const int N = model_->num_parameters();
  // The heading beta is an angle: its estimate is reported in (-pi, pi] (a solve may end a turn
  // away, which is the same calibration).
  for (int j = 0; j < N; ++j) {
    if (est->parameters[static_cast<std::size_t>(j)].name == "beta") {
      theta[j] = std::remainder(theta[j], 2 * M_PI);
    }
  }
  // The physical parameters (S, alpha, eps) of a sensor matrix G = (I+S) T_r^s C(eps) M have
  // exact symmetries: (alpha1, alpha2) and (alpha1 + pi, pi - alpha2) give the same T_r^s, and
  // eps_x + pi with 1 + Sy and 1 + Sz negated the same G. The estimate is reported on the branch
  // the LQ decomposition of its G gives (1 + S > 0, cos alpha2 > 0, angles in (-pi, pi]):
  // a gyro's early solves, with its scale factors barely determined by the Earth's rate alone,
  // ended on other branches and later ones warm-started there (alpha1 off by pi in 5 of 200
  // pipeline Monte Carlo runs; Sy = -2 after 26 static poses).
  if (const int iS = model_->index_of("Sx"), iA = model_->index_of("alpha1"),
      iE = model_->index_of("eps_x");
      iS >= 0 && iA >= 0 && iE >= 0) {
    AccelPhysical p;
    p.S = theta.segment<3>(iS);
    p.alpha = theta.segment<3>(iA);
    p.eps = theta.segment<3>(iE);
    const Mat3<double> G = AccelGFromPhysical(p, options_.context.mounting);
    AccelPhysical canonical;
    if (AccelPhysicalFromG(G, options_.context.mounting, &canonical, nullptr)) {
      theta.segment<3>(iS) = canonical.S;
      theta.segment<3>(iA) = canonical.alpha;
      theta.segment<3>(iE) = canonical.eps;
    }
  }
  if (model_->gauge_dimension() > 0) {
    ApplyMag22Gauge(*model_, &theta);
    est->gauge = ToString(options_.mag22_gauge);
  }
}

Eigen::MatrixXd Calibrator::RankAndCovariance(Eigen::VectorXd* theta, Estimate* est) const {
  const int N = model_->num_parameters();
  const int identifiable = N - model_->gauge_dimension();
  // Jacobian at the estimate, as the solver sees it (whitened, robust loss applied).
  ceres::Problem problem(ProblemOptions());
  for (auto* block : blocks_) problem.AddResidualBlock(block, loss_.get(), theta->data());
  const Eigen::MatrixXd J = DenseJacobian(&problem);
  const ScaledSvd scaled(J, options_.rank_tolerance);
  const Eigen::VectorXd& s = scaled.singular_values();
  est->rank = scaled.rank;
  est->condition = s[s.size() - 1] > 0 ? s[0] / s[s.size() - 1] : INFINITY;
  const int expected_rank = identifiable;
  if (est->rank < expected_rank) {
    est->warnings.push_back(
        fmt::format("rank {} of {}: the poses do not determine every parameter (pose diversity)",
                    est->rank, expected_rank));
  }

  // Covariance: Ceres' dense SVD for the models without a gauge; for mag22 the inverse Fisher
  // information restricted to the gauge's tangent space.
  if (model_->gauge_dimension() > 0) return GaugeCovariance(J, *theta);
  Eigen::MatrixXd cov(N, N);
  ceres::Covariance::Options cov_options;
  cov_options.algorithm_type = ceres::DENSE_SVD;
  cov_options.null_space_rank = est->rank < N ? N - est->rank : 0;
  cov_options.num_threads = 1;
  ceres::Covariance covariance(cov_options);
  std::vector<std::pair<const double*, const double*>> blocks = {{theta->data(), theta->data()}};
  if (covariance.Compute(blocks, &problem)) {
    covariance.GetCovarianceBlock(theta->data(), theta->data(), cov.data());
  } else {
    est->warnings.push_back("Ceres could not compute the covariance; using the pseudo-inverse");
    cov = scaled.PseudoInverseCovariance();
  }
  return cov;
}

Eigen::MatrixXd Calibrator::GaugeCovariance(const Eigen::MatrixXd& J,
                                            const Eigen::VectorXd& theta) const {
  // B (B^T J^T J B)^-1 B^T, B the gauge's tangent basis.
  const Eigen::MatrixXd B = Mag22GaugeTangentBasis(*model_, theta);
  const Eigen::MatrixXd JB = J * B;
  Eigen::JacobiSVD<Eigen::MatrixXd> svd_b(JB, Eigen::ComputeThinV);
  const Eigen::VectorXd sb = svd_b.singularValues();
  Eigen::VectorXd inv = Eigen::VectorXd::Zero(sb.size());
  for (int i = 0; i < sb.size(); ++i)
    if (sb[i] > options_.rank_tolerance * sb[0]) inv[i] = 1.0 / (sb[i] * sb[i]);
  Eigen::MatrixXd cov(model_->num_parameters(), model_->num_parameters());
  cov = B * svd_b.matrixV() * inv.asDiagonal() * svd_b.matrixV().transpose() * B.transpose();
  return cov;
}

void Calibrator::ComputeResiduals(const Eigen::VectorXd& theta, Estimate* est) const {
  const int n = num_poses();
  // Residuals, chi^2 (without the robust loss: the likelihood of the data as they are).
  // With drift a pose's whitened residual is its innovation (what the earlier poses did not
  // predict of it), so chi^2 = r^T C^-1 r and an outlier is judged against its own sigma.
  est->chi2 = 0;
  for (const auto& p : poses_) {
    PoseResidual r;
    r.raw = MeasuredMinusPredicted(p, theta, nullptr);
    r.whitened = p.weighted.sqrt_information * r.raw;
    est->residuals.push_back(r);
  }
  if (options_.drift.enabled()) {
    Eigen::VectorXd stacked(3 * n);
    for (int k = 0; k < n; ++k) {
      stacked.segment<3>(3 * k) = est->residuals[static_cast<std::size_t>(order_[k])].raw;
    }
    const Eigen::VectorXd innovations = gls_w_.triangularView<Eigen::Lower>() * stacked;
    for (int k = 0; k < n; ++k) {
      est->residuals[static_cast<std::size_t>(order_[k])].whitened = innovations.segment<3>(3 * k);
    }
    const TimeWindow& ref = poses_[static_cast<std::size_t>(order_.back())].host_window;
    est->bias_window = ref;
    est->drift = drift_;
    est->drift_scale_used = drift_scale_;
    if (!std::isfinite(est->drift.warmup_origin_s)) {
      // On the host's clock, as the bias window (corrected output's sigma uses both).
      est->drift.warmup_origin_s =
          poses_[static_cast<std::size_t>(order_.front())].host_window.t0_s;
    }
  }
  for (auto& r : est->residuals) {
    r.normalized = std::sqrt(r.whitened.squaredNorm() / 3.0);
    r.outlier = r.normalized > options_.outlier_threshold;
    est->chi2 += r.whitened.squaredNorm();
  }
  est->dof = 3 * n - est->rank;
  est->p_value = est->dof > 0 ? boost::math::gamma_q(est->dof / 2.0, est->chi2 / 2.0) : 1.0;
}

void Calibrator::CheckFitAndInflate(Estimate* est, Eigen::MatrixXd* cov) const {
  // The two-sided check on the innovations in time order (with drift, order_ is that order).
  std::vector<int> order = order_;
  if (order.empty()) {
    std::vector<TimeWindow> windows;
    for (const auto& p : poses_) windows.push_back(p.window);
    order = TimeOrder(windows);
  }
  std::vector<Eigen::Vector3d> innovations;
  for (int i : order) innovations.push_back(est->residuals[static_cast<std::size_t>(i)].whitened);
  est->fit = CheckFit(innovations, order, est->chi2, est->dof, options_.chi2_inflation_p_value,
                      options_.outlier_threshold);
  if (est->fit.verdict != FitVerdict::kOk) {
    est->warnings.push_back(est->fit.Message(ToString(model_->sensor())));
  }
  const int outliers =
      static_cast<int>(std::count_if(est->residuals.begin(), est->residuals.end(),
                                     [](const PoseResidual& r) { return r.outlier; }));
  if (outliers > 0) {
    est->warnings.push_back(fmt::format("{} pose(s) with normalised residual above {}", outliers,
                                        options_.outlier_threshold));
  }
  if (options_.inflate_covariance_by_chi2 && est->dof > 0 &&
      est->p_value < options_.chi2_inflation_p_value) {
    est->covariance_scale = est->chi2 / est->dof;
    *cov *= est->covariance_scale;
    est->warnings.push_back(fmt::format(
        "chi2/dof = {:.2f} (p = {:.2g}): the noise or the model does not explain the data; "
        "covariance inflated by that factor",
        est->covariance_scale, est->p_value));
  }
}

void Calibrator::MarkUndetermined(const Eigen::VectorXd& theta, Estimate* est) const {
  const int N = model_->num_parameters();
  if (est->rank >= N - model_->gauge_dimension()) return;
  // The pseudo-inverse gives a finite number for a parameter the data do not determine; say
  // infinity instead (the observability analysis names the directions).
  ObservabilityOptions analysis_options;
  analysis_options.rank_tolerance = options_.rank_tolerance;
  const DataReport data = AnalyzeData(*model_, theta, weighted_poses(), analysis_options);
  std::string names;
  for (int j = 0; j < N; ++j) {
    if (std::isinf(data.sigma[j])) {
      est->sigma[j] = INFINITY;
      names += (names.empty() ? "" : " ") + est->parameters[static_cast<std::size_t>(j)].name;
    }
  }
  if (!names.empty()) est->warnings.push_back("not determined by these poses: " + names);
}

}  // namespace turncal
