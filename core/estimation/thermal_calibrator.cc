#include "core/estimation/thermal_calibrator.h"

#include <ceres/ceres.h>
#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/SVD>
#include <algorithm>
#include <boost/math/special_functions/gamma.hpp>
#include <cmath>
#include <memory>
#include <optional>

#include "core/estimation/bias_drift.h"
#include "core/estimation/gls_whitening.h"
#include "core/estimation/scaled_svd.h"

namespace turncal {

bool ThermalOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (max_order < 0 || max_order > 5) return fail("max_order must be 0..5");
  if (!(distinct_resolution_c > 0) || !std::isfinite(distinct_resolution_c)) {
    return fail("distinct_resolution_c must be finite and > 0");
  }
  if (!std::isnan(t0_c) && !std::isfinite(t0_c)) return fail("t0_c must be finite (or NaN)");
  for (int k : orders) {
    if (k < 0) return fail("an order must be >= 0");
  }
  if (!(drop_below_sigmas >= 0) || !std::isfinite(drop_below_sigmas)) {
    return fail("drop_below_sigmas must be finite and >= 0");
  }
  return true;
}

namespace {

using RowJacobian = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Every pose's unwhitened residual (predicted - measured) and its Jacobian with respect to the
// coefficients, for the poses' temperatures and one basis.
class ThermalPoses {
 public:
  ThermalPoses(const MeasurementModel* model, const std::vector<WeightedPose>* poses,
               const std::vector<double>* temps_c, const ThermalBasis& basis)
      : model_(model), poses_(poses) {
    for (double t : *temps_c) design_.push_back(basis.Design(t));
    n_ = basis.num_coefficients();
  }
  int num_coefficients() const { return n_; }
  int num_poses() const { return static_cast<int>(poses_->size()); }
  // Pose i's raw residual, and its 3 x N Jacobian when `jacobian` is not null.
  bool Raw(int i, const double* c, Eigen::Vector3d* r, Eigen::MatrixXd* jacobian) const {
    const auto& d = design_[static_cast<std::size_t>(i)];
    const WeightedPose& p = (*poses_)[static_cast<std::size_t>(i)];
    const Eigen::VectorXd theta = d * Eigen::Map<const Eigen::VectorXd>(c, n_);
    if (jacobian == nullptr) {
      *r = model_->Predict(theta, p.pose) - p.measured;
    } else {
      Jacobian3 J;
      *r = model_->Predict(theta, p.pose, &J) - p.measured;
      *jacobian = J * d;
    }
    return r->allFinite();
  }
  const WeightedPose& pose(int i) const { return (*poses_)[static_cast<std::size_t>(i)]; }

 private:
  const MeasurementModel* model_;
  const std::vector<WeightedPose>* poses_;
  std::vector<Eigen::MatrixXd> design_;
  int n_ = 0;
};

// One pose's whitened residual (independent poses).
class PoseCost final : public ceres::CostFunction {
 public:
  PoseCost(std::shared_ptr<const ThermalPoses> poses, int i) : poses_(std::move(poses)), i_(i) {
    set_num_residuals(3);
    mutable_parameter_block_sizes()->push_back(poses_->num_coefficients());
  }
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    Eigen::Vector3d r;
    Eigen::MatrixXd J;
    const bool want = jacobians != nullptr && jacobians[0] != nullptr;
    if (!poses_->Raw(i_, parameters[0], &r, want ? &J : nullptr)) return false;
    const Eigen::Matrix3d& W = poses_->pose(i_).sqrt_information;
    Eigen::Map<Eigen::Vector3d> out(residuals);
    out = W * r;
    if (want) {
      Eigen::Map<RowJacobian>(jacobians[0], 3, poses_->num_coefficients()) = W * J;
    }
    return true;
  }

 private:
  std::shared_ptr<const ThermalPoses> poses_;
  int i_;
};

// All poses' residuals whitened together by W = L^-1 of their joint covariance in time order
// (bias drift): r_w = W r_raw, one block.
class GlsCost final : public ceres::CostFunction {
 public:
  GlsCost(std::shared_ptr<const ThermalPoses> poses, const GlsWhitening* gls)
      : poses_(std::move(poses)), gls_(gls) {
    set_num_residuals(3 * poses_->num_poses());
    mutable_parameter_block_sizes()->push_back(poses_->num_coefficients());
  }
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const int n = poses_->num_poses(), N = poses_->num_coefficients();
    const bool want = jacobians != nullptr && jacobians[0] != nullptr;
    Eigen::VectorXd raw(3 * n);
    Eigen::MatrixXd J_raw(want ? 3 * n : 0, N);
    Eigen::Vector3d r;
    Eigen::MatrixXd J;
    for (int k = 0; k < n; ++k) {
      const int i = gls_->order[static_cast<std::size_t>(k)];
      if (!poses_->Raw(i, parameters[0], &r, want ? &J : nullptr)) return false;
      raw.segment<3>(3 * k) = r;
      if (want) J_raw.middleRows(3 * k, 3) = J;
    }
    Eigen::Map<Eigen::VectorXd>(residuals, 3 * n) = gls_->W * raw;
    if (want) Eigen::Map<RowJacobian>(jacobians[0], 3 * n, N) = gls_->W * J_raw;
    return true;
  }

 private:
  std::shared_ptr<const ThermalPoses> poses_;
  const GlsWhitening* gls_;
};

struct Fit {
  ThermalBasis basis;  // scaled
  Eigen::VectorXd c;
  double chi2 = 0.0;  // 2 x the solver's final cost (the robust loss applied)
  bool ok = false;
  std::string error;
};

// The steps of one calibration over temperature: Prepare, Start, SelectOrders (or the orders
// given), then Covariance and Residuals of the chosen fit.
class ThermalCalibration {
 public:
  ThermalCalibration(const CalibratorOptions& options, const ThermalOptions& thermal)
      : options_(options), thermal_(thermal) {}

  ThermalEstimate Run(const std::vector<PoseRecord>& records) {
    ThermalEstimate est;
    if (!Prepare(records, &est)) return est;
    Fit fit = Start();
    if (fit.ok) fit = thermal_.orders.empty() ? SelectOrders(fit, &est) : GivenOrders(fit, &est);
    if (!fit.ok) {
      est.error = fit.error;
      return est;
    }
    Finish(fit, &est);
    return est;
  }

 private:
  bool Prepare(const std::vector<PoseRecord>& records, ThermalEstimate* est);
  Fit Start();
  Fit SelectOrders(Fit current, ThermalEstimate* est);
  Fit GivenOrders(const Fit& start, ThermalEstimate* est);
  Fit Solve(const ThermalBasis& basis, const Eigen::VectorXd& start, int max_iterations);
  // Each coefficient's sigma at the fit (the inverse Fisher information's diagonal).
  Eigen::VectorXd CoefficientSigma(const Fit& fit) const;
  // The whitened Jacobian and residual at the fit.
  void Whitened(const Fit& fit, Eigen::MatrixXd* J, Eigen::VectorXd* r) const;
  void Finish(const Fit& fit, ThermalEstimate* est);

  CalibratorOptions options_;
  ThermalOptions thermal_;
  std::unique_ptr<Calibrator> isothermal_;
  std::vector<WeightedPose> poses_;
  std::vector<double> temps_c_;
  std::vector<TimeWindow> windows_;
  std::optional<GlsWhitening> gls_;
  int max_allowed_order_ = 0;
  bool orders_capped_by_equations_ = false;  // max_allowed_order_ lowered for the equations
  Fit full_fit_;  // the order selection's start: every sensor parameter at the highest order
  double t0_c_ = 0.0, half_span_c_ = 1.0;
  std::vector<std::vector<double>> dropped_z_;  // per parameter: |c / sigma| of each dropped term
};

bool ThermalCalibration::Prepare(const std::vector<PoseRecord>& records, ThermalEstimate* est) {
  auto fail = [&](const std::string& m) {
    est->error = m;
    return false;
  };
  std::string error;
  if (!options_.IsValid(&error)) return fail("calibrator options: " + error);
  if (!thermal_.IsValid(&error)) return fail("thermal options: " + error);
  isothermal_ = std::make_unique<Calibrator>(options_);
  const MeasurementModel* model = isothermal_->model();
  if (model == nullptr) return fail(fmt::format("unknown model '{}'", options_.model));
  est->model = model->name();
  est->parameters = model->parameters();
  if (model->gauge_dimension() > 0) {
    return fail(fmt::format(
        "{} has a gauge ({} directions no turntable data resolve), whose choice over temperature "
        "is not defined: calibrate mag13 over temperature instead",
        model->name(), model->gauge_dimension()));
  }
  if (!thermal_.orders.empty() &&
      static_cast<int>(thermal_.orders.size()) != model->num_parameters()) {
    return fail(fmt::format("{} orders given for {}'s {} parameters", thermal_.orders.size(),
                            model->name(), model->num_parameters()));
  }
  for (std::size_t i = 0; i < records.size(); ++i) {
    const auto& t = records[i].temp_c;
    if (!t || !std::isfinite(*t)) {
      return fail(
          fmt::format("pose record {} has no temperature: a calibration over temperature "
                      "needs the device's temperature channel",
                      i + 1));
    }
    if (!isothermal_->add_pose(records[i], &error)) {
      return fail(fmt::format("pose record {}: {}", i + 1, error));
    }
    temps_c_.push_back(*t);
    windows_.push_back({records[i].sensor_start_s(), records[i].sensor_end_s()});
  }
  est->poses = static_cast<int>(records.size());
  if (3 * est->poses <= model->num_parameters()) {
    return fail(fmt::format("{} poses give {} equations for {}'s {} parameters", est->poses,
                            3 * est->poses, model->name(), model->num_parameters()));
  }
  std::vector<TimeWindow> drift_windows;
  isothermal_->planning_poses(&poses_, &drift_windows);
  if (options_.drift.enabled()) {
    std::vector<Eigen::Matrix3d> white;
    for (const auto& p : poses_) {
      white.push_back((p.sqrt_information.transpose() * p.sqrt_information).inverse());
    }
    GlsWhitening gls;
    if (!BuildGlsWhitening(drift_windows, white, options_.drift, &gls, &error)) {
      return fail("the drift model: " + error);
    }
    gls_ = std::move(gls);
    if (options_.identify_drift) {
      est->warnings.push_back(
          "the drift's strength is not identified over temperature: the prior drift model is "
          "used as given");
    }
  }
  const auto [lo, hi] = std::minmax_element(temps_c_.begin(), temps_c_.end());
  est->t_min_c = *lo;
  est->t_max_c = *hi;
  std::vector<double> sorted = temps_c_;
  std::sort(sorted.begin(), sorted.end());
  est->distinct_temperatures = 1;
  for (std::size_t i = 1, last = 0; i < sorted.size(); ++i) {
    if (sorted[i] - sorted[last] >= thermal_.distinct_resolution_c) {
      ++est->distinct_temperatures;
      last = i;
    }
  }
  max_allowed_order_ = std::min(thermal_.max_order, est->distinct_temperatures - 1);
  // Nor more coefficients than equations (3 a pose, 1 left over): early in a ramp a few poses at
  // as many temperatures would otherwise start the order selection from more unknowns than
  // equations (rank-deficient, every sigma infinite).
  int sensor_parameters = 0;
  for (const ParameterInfo& info : model->parameters()) {
    sensor_parameters += info.kind == ParameterKind::kSensor ? 1 : 0;
  }
  const int others = model->num_parameters() - sensor_parameters;
  orders_capped_by_equations_ = false;
  while (max_allowed_order_ > 0 &&
         sensor_parameters * (max_allowed_order_ + 1) + others >= 3 * est->poses) {
    --max_allowed_order_;
    orders_capped_by_equations_ = true;
  }
  t0_c_ = std::isnan(thermal_.t0_c) ? 0.5 * (*lo + *hi) : thermal_.t0_c;
  half_span_c_ = std::max({0.5 * (*hi - *lo), std::abs(*hi - t0_c_), std::abs(*lo - t0_c_), 1.0});
  dropped_z_.assign(static_cast<std::size_t>(model->num_parameters()), {});
  full_fit_ = Fit{};
  return true;
}

Fit ThermalCalibration::Start() {
  const Estimate iso = isothermal_->solve();
  if (!iso.ok) {
    Fit f;
    f.error = "the isothermal start failed: " + iso.error;
    return f;
  }
  ThermalBasis basis = ThermalBasis::Constant(static_cast<int>(iso.theta.size()), t0_c_);
  basis.scale_c = half_span_c_;
  return Solve(basis, iso.theta, options_.max_iterations);
}

Fit ThermalCalibration::Solve(const ThermalBasis& basis, const Eigen::VectorXd& start,
                              int max_iterations) {
  Fit f;
  f.basis = basis;
  f.c = start;
  auto poses =
      std::make_shared<const ThermalPoses>(isothermal_->model(), &poses_, &temps_c_, basis);
  ceres::Problem problem;
  std::unique_ptr<ceres::LossFunction> loss;
  if (gls_) {
    problem.AddResidualBlock(new GlsCost(poses, &*gls_), nullptr, f.c.data());
  } else {
    for (int i = 0; i < poses->num_poses(); ++i) {
      ceres::LossFunction* l = nullptr;
      if (options_.loss == RobustLoss::kHuber) l = new ceres::HuberLoss(options_.loss_scale);
      if (options_.loss == RobustLoss::kCauchy) l = new ceres::CauchyLoss(options_.loss_scale);
      problem.AddResidualBlock(new PoseCost(poses, i), l, f.c.data());
    }
  }
  ceres::Solver::Options solver;
  solver.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  solver.linear_solver_type = ceres::DENSE_QR;
  solver.max_num_iterations = max_iterations;
  solver.function_tolerance = options_.function_tolerance;
  solver.gradient_tolerance = options_.gradient_tolerance;
  solver.parameter_tolerance = options_.parameter_tolerance;
  solver.logging_type = ceres::SILENT;
  solver.num_threads = 1;
  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);
  f.chi2 = 2.0 * summary.final_cost;
  f.ok = summary.IsSolutionUsable() && f.c.allFinite() && std::isfinite(f.chi2);
  if (!f.ok) f.error = "the solver failed: " + summary.message;
  return f;
}

Eigen::VectorXd ThermalCalibration::CoefficientSigma(const Fit& fit) const {
  Eigen::MatrixXd J;
  Eigen::VectorXd r;
  Whitened(fit, &J, &r);
  Eigen::VectorXd scale = J.colwise().norm().transpose();
  for (int j = 0; j < scale.size(); ++j) scale[j] = scale[j] > 0 ? 1.0 / scale[j] : 1.0;
  const Eigen::MatrixXd Js = J * scale.asDiagonal();
  const Eigen::MatrixXd info = Js.transpose() * Js;
  Eigen::LDLT<Eigen::MatrixXd> ldlt(info);
  const Eigen::MatrixXd cov = ldlt.solve(Eigen::MatrixXd::Identity(info.rows(), info.cols()));
  return scale.cwiseProduct(cov.diagonal().cwiseMax(0.0).cwiseSqrt());
}

Fit ThermalCalibration::SelectOrders(Fit current, ThermalEstimate* est) {
  const MeasurementModel& model = *isothermal_->model();
  // From every sensor parameter at the highest order the temperatures carry (the mounting and
  // the installation do not depend on the sensor's temperature: order 0).
  ThermalBasis full = current.basis;
  for (int p = 0; p < model.num_parameters(); ++p) {
    full.orders[static_cast<std::size_t>(p)] =
        model.parameters()[static_cast<std::size_t>(p)].kind == ParameterKind::kSensor
            ? max_allowed_order_
            : 0;
  }
  current = Solve(full, current.basis.Raised(current.c, full), options_.max_iterations);
  full_fit_ = current;
  est->solves = 2;
  // Then, one at a time, the highest coefficient the data show closest to zero is dropped while
  // it is within drop_below_sigmas of zero.
  while (current.ok) {
    const Eigen::VectorXd sigma = CoefficientSigma(current);
    int best_p = -1;
    double best_z = thermal_.drop_below_sigmas;
    for (int p = 0; p < current.basis.num_parameters(); ++p) {
      const int k = current.basis.orders[static_cast<std::size_t>(p)];
      if (k == 0) continue;
      const int j = current.basis.index(p, k);
      const double z = std::abs(current.c[j]) / sigma[j];
      if (std::isfinite(z) && z < best_z) best_z = z, best_p = p;
    }
    if (best_p < 0) break;
    ThermalBasis lower = current.basis;
    --lower.orders[static_cast<std::size_t>(best_p)];
    Eigen::VectorXd c(lower.num_coefficients());
    for (int p = 0; p < lower.num_parameters(); ++p) {
      for (int j = 0; j <= lower.orders[static_cast<std::size_t>(p)]; ++j) {
        c[lower.index(p, j)] = current.c[current.basis.index(p, j)];
      }
    }
    Fit f = Solve(lower, c, options_.max_iterations);
    ++est->solves;
    if (!f.ok) break;
    dropped_z_[static_cast<std::size_t>(best_p)].push_back(best_z);
    current = std::move(f);
  }
  for (int p = 0; p < current.basis.num_parameters(); ++p) {
    const ParameterInfo& info = model.parameters()[static_cast<std::size_t>(p)];
    const auto& dropped = dropped_z_[static_cast<std::size_t>(p)];
    const int k = current.basis.orders[static_cast<std::size_t>(p)];
    std::string reason;
    if (info.kind != ParameterKind::kSensor) {
      reason =
          "order 0: a mounting or installation parameter does not depend on the sensor's "
          "temperature";
    } else if (max_allowed_order_ == 0 && !orders_capped_by_equations_) {
      reason = fmt::format("order 0: {} distinct temperature(s) carry no higher order",
                           est->distinct_temperatures);
    } else if (dropped.empty() && orders_capped_by_equations_) {
      reason = fmt::format(
          "order {}: the highest the {} poses' {} equations carry for {} parameters (more poses "
          "raise it)",
          k, est->poses, 3 * est->poses, model.num_parameters());
    } else if (dropped.empty()) {
      reason = fmt::format(
          "order {}: the highest the {} temperatures carry (max_order {}); its "
          "top coefficient is at least {:g} sigma from zero",
          k, est->distinct_temperatures, thermal_.max_order, thermal_.drop_below_sigmas);
    } else {
      reason = fmt::format("order {}: the coefficient(s) above it were", k);
      for (std::size_t j = 0; j < dropped.size(); ++j) {
        reason += fmt::format("{} {:.2f}", j ? "," : "", dropped[j]);
      }
      reason += fmt::format(" sigma from zero (dropped below {:g})", thermal_.drop_below_sigmas);
    }
    est->order_reasons.push_back(reason);
  }
  return current;
}

Fit ThermalCalibration::GivenOrders(const Fit& start, ThermalEstimate* est) {
  ThermalBasis basis = start.basis;
  for (std::size_t p = 0; p < thermal_.orders.size(); ++p) {
    const int asked = thermal_.orders[p];
    basis.orders[p] = std::min(asked, max_allowed_order_);
    if (asked > max_allowed_order_) {
      est->order_reasons.push_back(
          orders_capped_by_equations_
              ? fmt::format("order {}: {} asked, but the {} poses' {} equations carry at most "
                            "order {}",
                            basis.orders[p], asked, est->poses, 3 * est->poses, max_allowed_order_)
              : fmt::format("order {}: {} asked, but {} distinct temperature(s) carry at most "
                            "order {}",
                            basis.orders[p], asked, est->distinct_temperatures,
                            max_allowed_order_));
      est->warnings.push_back(
          fmt::format("{}: {}", est->parameters[p].name, est->order_reasons.back()));
    } else {
      est->order_reasons.push_back(fmt::format("order {}: as asked", asked));
    }
  }
  est->solves = 2;
  return Solve(basis, start.basis.Raised(start.c, basis), options_.max_iterations);
}

void ThermalCalibration::Whitened(const Fit& fit, Eigen::MatrixXd* J, Eigen::VectorXd* r) const {
  const ThermalPoses poses(isothermal_->model(), &poses_, &temps_c_, fit.basis);
  const int n = poses.num_poses(), N = poses.num_coefficients();
  Eigen::MatrixXd J_raw(3 * n, N);
  Eigen::VectorXd raw(3 * n);
  Eigen::Vector3d ri;
  Eigen::MatrixXd Ji;
  for (int i = 0; i < n; ++i) {
    poses.Raw(i, fit.c.data(), &ri, &Ji);
    const int row = gls_ ? static_cast<int>(std::find(gls_->order.begin(), gls_->order.end(), i) -
                                            gls_->order.begin())
                         : i;
    const Eigen::Matrix3d W = gls_ ? Eigen::Matrix3d::Identity() : poses.pose(i).sqrt_information;
    raw.segment<3>(3 * row) = W * ri;
    J_raw.middleRows(3 * row, 3) = W * Ji;
  }
  if (gls_) {
    *r = gls_->W * raw;
    *J = gls_->W * J_raw;
  } else {
    *r = raw;
    *J = J_raw;
  }
}

void ThermalCalibration::Finish(const Fit& fit, ThermalEstimate* est) {
  const int n = static_cast<int>(poses_.size()), N = fit.basis.num_coefficients();
  Eigen::MatrixXd J;
  Eigen::VectorXd r;
  Whitened(fit, &J, &r);
  // Rank and covariance of the scaled coefficients: the column-scaled Jacobian's SVD.
  const ScaledSvd scaled(J, options_.rank_tolerance);
  est->rank = scaled.rank;
  Eigen::MatrixXd cov = scaled.PseudoInverseCovariance();
  // With coefficients dropped by the order selection, the kept ones' covariance is their block of
  // the full model's: conditional on the chosen orders it ignores that a dropped coefficient may
  // be a fraction of a sigma from zero, which near the range's ends (where dT^k is largest) was
  // 10-18 % overconfident (accel13 consumer through the pipeline, 400 runs: 7 of 39 held-out
  // values outside std z [0.9, 1.1] with chosen orders, 1 of 70 with the truth's).
  int dropped_total = 0;
  for (const auto& d : dropped_z_) dropped_total += static_cast<int>(d.size());
  if (dropped_total > 0 && full_fit_.ok) {
    Eigen::MatrixXd J_full;
    Eigen::VectorXd r_full;
    Whitened(full_fit_, &J_full, &r_full);
    const ScaledSvd full_svd(J_full, options_.rank_tolerance);
    if (full_svd.rank == J_full.cols()) {
      const Eigen::MatrixXd cov_full = full_svd.PseudoInverseCovariance();
      std::vector<int> to_full(static_cast<std::size_t>(N));
      for (int p = 0; p < fit.basis.num_parameters(); ++p) {
        for (int j = 0; j <= fit.basis.orders[static_cast<std::size_t>(p)]; ++j) {
          to_full[static_cast<std::size_t>(fit.basis.index(p, j))] = full_fit_.basis.index(p, j);
        }
      }
      for (int a = 0; a < N; ++a) {
        for (int b = 0; b < N; ++b) {
          cov(a, b) =
              cov_full(to_full[static_cast<std::size_t>(a)], to_full[static_cast<std::size_t>(b)]);
        }
      }
    }
  }
  const Eigen::MatrixXd& V = scaled.svd.matrixV();
  // Residuals per record (with drift: innovations, in time order back to the record's index).
  est->residuals.assign(static_cast<std::size_t>(n), PoseResidual{});
  std::vector<int> order(static_cast<std::size_t>(n));
  for (int k = 0; k < n; ++k) order[static_cast<std::size_t>(k)] = gls_ ? gls_->order[k] : k;
  if (!gls_) order = TimeOrder(windows_);
  std::vector<Eigen::Vector3d> innovations;
  for (int k = 0; k < n; ++k) {
    const int i = order[static_cast<std::size_t>(k)];
    const int row = gls_ ? k : i;
    PoseResidual& pr = est->residuals[static_cast<std::size_t>(i)];
    pr.whitened = r.segment<3>(3 * row);
    pr.normalized = std::sqrt(pr.whitened.squaredNorm() / 3.0);
    pr.outlier = pr.normalized > options_.outlier_threshold;
    innovations.push_back(pr.whitened);
  }
  const ThermalPoses poses(isothermal_->model(), &poses_, &temps_c_, fit.basis);
  for (int i = 0; i < n; ++i) {
    Eigen::Vector3d raw;
    poses.Raw(i, fit.c.data(), &raw, nullptr);
    est->residuals[static_cast<std::size_t>(i)].raw = -raw;  // measured - predicted
  }
  est->chi2 = r.squaredNorm();
  // Coefficients the order selection estimated and dropped for being within drop_below_sigmas of
  // zero still count against the dof: the chosen model's chi^2 is the full model's plus their
  // tiny z^2 (E[z^2 | |z| < 0.25] = 0.02, not 1), so with 3n - rank alone chi^2 came out small
  // and its p-values leaned to 1 (KS p = 0.005 over 1000 pipeline runs of mag13 consumer).
  est->dof = 3 * n - est->rank - dropped_total;
  est->p_value = est->dof > 0 ? boost::math::gamma_q(est->dof / 2.0, est->chi2 / 2.0) : 1.0;
  est->fit = CheckFit(innovations, order, est->chi2, est->dof, options_.chi2_inflation_p_value,
                      options_.outlier_threshold);
  const MeasurementModel& model = *isothermal_->model();
  if (est->fit.verdict != FitVerdict::kOk) {
    est->warnings.push_back(est->fit.Message(ToString(model.sensor())));
  }
  if (options_.inflate_covariance_by_chi2 && est->dof > 0 &&
      est->p_value < options_.chi2_inflation_p_value) {
    est->covariance_scale = est->chi2 / est->dof;
    cov *= est->covariance_scale;
    est->warnings.push_back(fmt::format(
        "chi2/dof = {:.2f} (p = {:.2g}): the noise or the thermal model does not explain the "
        "data; covariance inflated by that factor",
        est->covariance_scale, est->p_value));
  }
  if (est->rank < N) {
    est->warnings.push_back(
        fmt::format("rank {} of {}: the poses and temperatures do not determine every coefficient",
                    est->rank, N));
  }
  // Into the unscaled basis: coefficients per degree C^j.
  const Eigen::VectorXd to = fit.basis.ToUnscaled();
  est->basis = fit.basis.Unscaled();
  est->coefficients = to.asDiagonal() * fit.c;
  est->covariance = to.asDiagonal() * cov * to.asDiagonal();
  est->sigma = est->covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
  if (est->rank < N) {
    // A coefficient in the null space has no finite sigma.
    const Eigen::MatrixXd null = V.rightCols(N - est->rank);
    for (int j = 0; j < N; ++j) {
      if (null.row(j).norm() > 1e-6) est->sigma[j] = INFINITY;
    }
  }
  for (int j = 0; j < N; ++j) {
    est->coefficient_names.push_back(est->basis.CoefficientName(est->parameters, j));
  }
  est->ok = true;
}

}  // namespace

ThermalEstimate CalibrateOverTemperature(const CalibratorOptions& options,
                                         const std::vector<PoseRecord>& records,
                                         const ThermalOptions& thermal) {
  ThermalCalibration calibration(options, thermal);
  return calibration.Run(records);
}

}  // namespace turncal
