#include "core/estimation/free_calibrator.h"

#include <ceres/ceres.h>
#include <fmt/format.h>

#include <Eigen/SVD>
#include <boost/math/special_functions/gamma.hpp>
#include <cmath>
#include <set>

namespace turncal {

bool FreeCalibratorOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& why) {
    if (error) *error = why;
    return false;
  };
  if (passes < 1 || max_iterations < 1) return fail("passes and iterations must be positive");
  if (!(chi2_inflation_p_value > 0 && chi2_inflation_p_value < 1)) {
    return fail("the chi^2 inflation's p-value must be in (0, 1)");
  }
  if (!(min_relative_singular >= 0) || !(min_coverage >= 0 && min_coverage <= 1)) {
    return fail("the gate's limits must be a relative singular value >= 0 and a share in [0, 1]");
  }
  return observability.IsValid(error);
}

namespace {

struct Evaluated {
  Eigen::VectorXd r;
  Eigen::MatrixXd J, Ju;  // d r / d theta, d r / d upstream
};

Evaluated Evaluate(const std::vector<FreeTerm>& terms, const Eigen::VectorXd& theta,
                   const Eigen::VectorXd& upstream, std::vector<FreeTermResidual>* out) {
  int m = 0;
  for (const auto& t : terms) m += t.cost->num_residuals();
  const int n = static_cast<int>(theta.size()), p = static_cast<int>(upstream.size());
  Evaluated e{Eigen::VectorXd::Zero(m), Eigen::MatrixXd::Zero(m, n), Eigen::MatrixXd::Zero(m, p)};
  int row = 0;
  for (const auto& t : terms) {
    const int k = t.cost->num_residuals();
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> jt(k, n), ju(k, p);
    std::vector<const double*> blocks = {theta.data()};
    std::vector<double*> jac = {jt.data()};
    if (t.upstream) {
      blocks.push_back(upstream.data());
      jac.push_back(ju.data());
    }
    Eigen::VectorXd r(k);
    if (!t.cost->Evaluate(blocks.data(), r.data(), jac.data())) {
      r.setConstant(NAN);
      jt.setZero();
      ju.setZero();
    }
    e.r.segment(row, k) = r;
    e.J.middleRows(row, k) = jt;
    if (t.upstream) e.Ju.middleRows(row, k) = ju;
    if (out) out->push_back({t.interval, t.kind, r});
    row += k;
  }
  return e;
}

}  // namespace

FreeEstimate CalibrateFree(const FreeModel& model, const FreeData& data,
                           const FreeCalibratorOptions& options) {
  FreeEstimate out;
  Estimate& est = out.estimate;
  est.model = model.name();
  est.parameters = model.parameters();
  const int n = model.num_parameters();
  out.relative_scale =
      model.sensor() == SensorKind::kMagnetometer && !(data.context.field_magnitude > 0);
  for (const auto& iv : data.intervals) {
    bool has = true;
    for (SensorKind k :
         {SensorKind::kAccelerometer, SensorKind::kGyroscope, SensorKind::kMagnetometer}) {
      const bool present = k == SensorKind::kAccelerometer ? iv.acc.has_value()
                           : k == SensorKind::kGyroscope   ? iv.gyr.has_value()
                                                           : iv.mag.has_value();
      if (model.Needs(k) && !present) has = false;
    }
    out.intervals += has;
  }
  est.poses = out.intervals;
  Eigen::VectorXd theta;
  if (!model.Start(data, &theta, &est.error)) return out;
  const Eigen::VectorXd upstream = data.upstream_theta;

  // Solve, re-whitening at each result.
  std::vector<FreeTerm> terms;
  for (int pass = 0; pass < options.passes; ++pass) {
    terms = model.Terms(data, theta);
    if (terms.empty()) {
      est.error = fmt::format("{}: the intervals give no residuals", model.name());
      return out;
    }
    ceres::Problem::Options po;
    po.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    ceres::Problem problem(po);
    Eigen::VectorXd up = upstream;
    for (const auto& t : terms) {
      if (t.upstream) {
        problem.AddResidualBlock(t.cost.get(), nullptr, theta.data(), up.data());
      } else {
        problem.AddResidualBlock(t.cost.get(), nullptr, theta.data());
      }
    }
    if (up.size() > 0 && problem.HasParameterBlock(up.data())) {
      problem.SetParameterBlockConstant(up.data());
    }
    ceres::Solver::Options so;
    so.linear_solver_type = ceres::DENSE_QR;
    so.max_num_iterations = options.max_iterations;
    so.function_tolerance = 1e-12;
    so.gradient_tolerance = 1e-14;
    so.parameter_tolerance = 1e-12;
    so.num_threads = 1;
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem, &summary);
    est.iterations += static_cast<int>(summary.iterations.size());
    est.termination = ceres::TerminationTypeToString(summary.termination_type);
    est.solve_time_s += summary.total_time_in_seconds;
    if (!summary.IsSolutionUsable() || !theta.allFinite()) {
      est.error = fmt::format("{}: the solve failed ({})", model.name(), summary.message);
      return out;
    }
  }
  terms = model.Terms(data, theta);
  const Evaluated ev = Evaluate(terms, theta, upstream, &out.terms);
  if (!ev.r.allFinite()) {
    est.error = fmt::format("{}: a residual is not finite at the solution", model.name());
    return out;
  }
  out.residuals = static_cast<int>(ev.r.size());
  est.theta = theta;
  est.ok = true;

  // Rank and covariance in scaled units.
  const Eigen::VectorXd scales = model.Scales(data, theta);
  out.analysis = AnalyzeRank(ev.J, model.parameters(), scales, options.observability);
  est.rank = out.analysis.rank;
  est.condition = out.analysis.condition;
  const Eigen::MatrixXd Js = ev.J * scales.asDiagonal();
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(Js, Eigen::ComputeFullV);
  const Eigen::VectorXd& s = svd.singularValues();
  Eigen::MatrixXd pinv = Eigen::MatrixXd::Zero(n, n);
  for (int i = 0; i < est.rank && i < s.size(); ++i) {
    pinv += svd.matrixV().col(i) * svd.matrixV().col(i).transpose() / (s[i] * s[i]);
  }
  Eigen::MatrixXd cov = scales.asDiagonal() * pinv * scales.asDiagonal();
  if (upstream.size() > 0 && data.upstream_covariance.rows() == upstream.size()) {
    const Eigen::MatrixXd G = cov * ev.J.transpose() * ev.Ju;  // d theta / d upstream
    cov += G * data.upstream_covariance * G.transpose();
  }

  // chi^2 and the fit check.
  est.chi2 = ev.r.squaredNorm();
  est.dof = out.residuals - est.rank;
  FitCheck& fit = est.fit;
  fit.chi2 = est.chi2;
  fit.dof = est.dof;
  if (est.dof > 0) {
    fit.p_upper = boost::math::gamma_q(est.dof / 2.0, est.chi2 / 2.0);
    fit.p_lower = boost::math::gamma_p(est.dof / 2.0, est.chi2 / 2.0);
  }
  est.p_value = fit.p_upper;
  for (const auto& t : out.terms) {
    const double normalized = std::sqrt(t.whitened.squaredNorm() / t.whitened.size());
    if (normalized > fit.worst_normalized) {
      fit.worst_normalized = normalized;
      fit.worst_pose = t.interval;
    }
  }
  if (est.dof > 0 && fit.p_upper < options.chi2_inflation_p_value) {
    fit.verdict = FitVerdict::kTooLarge;
    fit.cause =
        fit.worst_normalized > options.outlier_threshold
            ? fmt::format(
                  "interval {} has the largest residual ({:.1f} sigma): it may not have "
                  "been still, or the model does not fit it",
                  fit.worst_pose, fit.worst_normalized)
            : "the intervals' noise is larger than their own scatter says (bias instability, a "
              "hand's placement), or the model does not fit";
    if (options.inflate_covariance_by_chi2) {
      est.covariance_scale = est.chi2 / est.dof;
      cov *= est.covariance_scale;
      est.warnings.push_back(
          fmt::format("chi2/dof = {:.2f} (p = {:.2g}): covariance inflated by that factor",
                      est.covariance_scale, fit.p_upper));
    }
  } else if (est.dof > 0 && fit.p_lower < options.chi2_inflation_p_value) {
    fit.verdict = FitVerdict::kTooSmall;
    fit.cause = "the residuals are smaller than the intervals' noise says";
  }
  est.covariance = cov;
  est.sigma = cov.diagonal().cwiseMax(0).cwiseSqrt();

  // Named null and weak directions.
  std::set<std::string> undetermined, weak;
  for (const auto& d : out.analysis.null) {
    for (int i = 0; i < n; ++i) {
      if (std::abs(d.scaled[i]) > options.observability.involvement) {
        est.sigma[i] = INFINITY;
        undetermined.insert(model.parameters()[i].name);
      }
    }
  }
  for (const auto& d : out.analysis.weak) {
    if (d.relative_singular_value >= options.min_relative_singular) continue;
    for (const auto& name : d.involved) weak.insert(name);
  }
  for (const auto& p : model.parameters()) {
    if (undetermined.count(p.name)) out.undetermined.push_back(p.name);
    if (weak.count(p.name) && !undetermined.count(p.name)) out.weak.push_back(p.name);
  }

  // Coverage of the corrected triad's directions.
  for (const auto& iv : data.intervals) {
    const Eigen::Vector3d d = model.Direction(data, theta, iv);
    if (d.squaredNorm() > 0) out.directions.push_back(d);
  }
  out.coverage = CoverageOf(out.directions);

  // The gate.
  auto refuse = [&](std::string why) { out.gate_reasons.push_back(std::move(why)); };
  auto join = [](const std::vector<std::string>& v) {
    std::string text;
    for (const auto& x : v) text += (text.empty() ? "" : ", ") + x;
    return text;
  };
  if (est.rank < n) {
    refuse(fmt::format("rank {} of {}: the data do not determine {}", est.rank, n,
                       join(out.undetermined)));
  } else if (!out.weak.empty()) {
    refuse(fmt::format(
        "the weakest direction ({:.2g} of the strongest) involves {}",
        out.analysis.weak.empty() ? 0.0 : out.analysis.weak.back().relative_singular_value,
        join(out.weak)));
  }
  if (options.min_coverage > 0 && out.coverage.fraction() < options.min_coverage) {
    refuse(fmt::format("coverage {:.1f} % of the sphere is below the {:.1f} % required",
                       100 * out.coverage.fraction(), 100 * options.min_coverage));
  }
  for (const auto& [name, limit] : options.max_sigma) {
    const int i = model.index_of(name);
    if (i >= 0 && !(est.sigma[i] <= limit)) {
      refuse(
          fmt::format("sigma of {} is {:.3g}, above its limit {:.3g}", name, est.sigma[i], limit));
    }
  }
  out.gate_passed = out.gate_reasons.empty();
  return out;
}

}  // namespace turncal
