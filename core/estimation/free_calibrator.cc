#include "core/estimation/free_calibrator.h"

#include "core/estimation/free_drift.h"

#include <ceres/ceres.h>
#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/SVD>
#include <algorithm>
#include <boost/math/special_functions/gamma.hpp>
#include <cmath>
#include <memory>
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
  if (precision && !precision->IsValid(error)) return false;
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

Eigen::MatrixXd FreeJacobian(const FreeModel& model, const FreeData& data,
                             const Eigen::VectorXd& theta) {
  const std::vector<FreeTerm> terms = model.Terms(data, theta);
  return Evaluate(terms, theta, data.upstream_theta, nullptr).J;
}

std::vector<MisfitFigure> SummarizeMisfits(const std::vector<FreeModel::Misfit>& misfits) {
  std::vector<MisfitFigure> out;
  for (const auto& m : misfits) {
    auto it = std::find_if(out.begin(), out.end(), [&](const auto& f) { return f.kind == m.kind; });
    if (it == out.end()) it = out.insert(out.end(), MisfitFigure{m.kind, 0, 0.0, 0.0});
    ++it->count;
    it->rms += m.value * m.value;
    it->max_abs = std::max(it->max_abs, std::abs(m.value));
  }
  for (auto& f : out) f.rms = std::sqrt(f.rms / std::max(1, f.count));
  return out;
}

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

  // The drift of the triads whose bias the model carries, and the reference window: the latest
  // interval's (on the sensor's clock; the bias parameters are then the bias over it).
  // Every triad with a drift model: with the model's bias column for it, or none (its drift
  // still reaches terms through their extra_drift: gyro9's accelerometer).
  std::vector<FreeDriftTriad> drifts;
  for (SensorKind kind :
       {SensorKind::kAccelerometer, SensorKind::kGyroscope, SensorKind::kMagnetometer}) {
    const BiasDrift& d = kind == SensorKind::kAccelerometer  ? data.context.acc_drift
                         : kind == SensorKind::kMagnetometer ? data.context.mag_drift
                                                             : data.context.gyr_drift;
    if (!d.enabled() || !model.Needs(kind)) continue;
    int column = -1;
    for (const auto& [k, c] : model.BiasColumns()) {
      if (k == kind) column = c;
    }
    drifts.push_back({kind, column, d});
  }
  TimeWindow reference;
  double origin_s = INFINITY;
  const FreeInterval* latest = nullptr;
  for (const auto& iv : data.intervals) {
    origin_s = std::min(origin_s, iv.sensor_start_s());
    if (!latest || iv.sensor_end_s() > latest->sensor_end_s()) latest = &iv;
  }
  if (!drifts.empty() && latest) {
    reference = TimeWindow{latest->sensor_start_s(), latest->sensor_end_s()};
    out.bias_window = reference;
    out.bias_window_host = TimeWindow{latest->t_start_s, latest->t_end_s};
  } else {
    drifts.clear();
  }
  // The terms are whitened together when a drift correlates them or they share noise.
  bool joint = !drifts.empty();
  for (const auto& t : model.Terms(data, theta)) joint |= !t.shared.empty();
  auto whitener = [&](const std::vector<FreeTerm>& t, const Eigen::VectorXd& at) {
    const Evaluated e = Evaluate(t, at, upstream, nullptr);
    for (const auto& term : t) origin_s = std::min(origin_s, term.window.t0_s);
    return FreeDriftWhitener(t, e.J, drifts, reference, origin_s);
  };

  // Solve, re-whitening at each result.
  std::vector<FreeTerm> terms;
  std::unique_ptr<StackedFreeCost> stacked;
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
    if (joint) {
      stacked = std::make_unique<StackedFreeCost>(
          terms, whitener(terms, theta), model.num_parameters(), static_cast<int>(upstream.size()));
      if (stacked->uses_upstream()) {
        problem.AddResidualBlock(stacked.get(), nullptr, theta.data(), up.data());
      } else {
        problem.AddResidualBlock(stacked.get(), nullptr, theta.data());
      }
    } else {
      for (const auto& t : terms) {
        if (t.upstream) {
          problem.AddResidualBlock(t.cost.get(), nullptr, theta.data(), up.data());
        } else {
          problem.AddResidualBlock(t.cost.get(), nullptr, theta.data());
        }
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
  Evaluated ev = Evaluate(terms, theta, upstream, &out.terms);
  if (joint && ev.r.allFinite()) {
    // The innovations: the terms whitened together.
    const Eigen::MatrixXd W = whitener(terms, theta);
    ev.r = W * ev.r;
    ev.J = W * ev.J;
    if (ev.Ju.cols() > 0) ev.Ju = W * ev.Ju;
    int row = 0;
    for (auto& t : out.terms) {
      const auto k = t.whitened.size();
      t.whitened = ev.r.segment(row, k);
      row += static_cast<int>(k);
    }
  }
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
  const bool with_upstream = upstream.size() > 0 &&
                             data.upstream_covariance.rows() == upstream.size() &&
                             data.upstream_covariance.allFinite();
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(
      Js, with_upstream ? (Eigen::ComputeFullU | Eigen::ComputeFullV) : Eigen::ComputeFullV);
  const Eigen::VectorXd& s = svd.singularValues();
  Eigen::MatrixXd pinv = Eigen::MatrixXd::Zero(n, n);
  for (int i = 0; i < est.rank && i < s.size(); ++i) {
    pinv += svd.matrixV().col(i) * svd.matrixV().col(i).transpose() / (s[i] * s[i]);
  }
  Eigen::MatrixXd cov = scales.asDiagonal() * pinv * scales.asDiagonal();
  if (with_upstream) {
    const Eigen::MatrixXd G = cov * ev.J.transpose() * ev.Ju;  // d theta / d upstream
    cov += G * data.upstream_covariance * G.transpose();
  }

  // chi^2 and the fit check.
  est.chi2 = ev.r.squaredNorm();
  if (with_upstream && est.rank < ev.r.size()) {
    // The upstream estimate's error is in every residual too: in the residuals' space, left after
    // the fit (N, the complement of J's columns), they have the covariance N^T (I + A C_u A^T) N,
    // A = d r / d upstream. chi^2 against it (without it, a noisy upstream read as misfit: gyro9
    // on an accelerometer with 8 mg per sample had chi^2/dof 1.09).
    const Eigen::MatrixXd N = svd.matrixU().rightCols(ev.r.size() - est.rank);
    const Eigen::MatrixXd NA = N.transpose() * ev.Ju;
    Eigen::MatrixXd C = NA * data.upstream_covariance * NA.transpose();
    C.diagonal().array() += 1.0;
    const Eigen::VectorXd y = N.transpose() * ev.r;
    const Eigen::LLT<Eigen::MatrixXd> llt(C);
    if (llt.info() == Eigen::Success) est.chi2 = y.dot(llt.solve(y));
  }
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
  out.before = SummarizeMisfits(model.Misfits(data, model.Identity(data)));
  out.after = SummarizeMisfits(model.Misfits(data, theta));

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
  if (options.precision) {
    const GateOptions& g = *options.precision;
    if (est.dof < g.min_dof) {
      refuse(fmt::format("{} redundant equations: the fit check needs at least {}", est.dof,
                         g.min_dof));
    } else if (est.p_value < g.min_p_value) {
      refuse(fmt::format(
          "chi2/dof {:.2f} (p {:.2g}, below {:.2g}): {}", est.dof > 0 ? est.chi2 / est.dof : 0.0,
          est.p_value, g.min_p_value,
          est.fit.cause.empty() ? "the noise model or the model does not fit" : est.fit.cause));
    }
    for (int i = 0; i < n; ++i) {
      ParameterInfo as;
      const double limit = FreeToleranceFor(model.parameters()[i], g, &as);
      if (limit > 0 && std::isfinite(est.sigma[i]) && !(est.sigma[i] <= limit)) {
        refuse(fmt::format("{}: sigma {} exceeds the tolerance {}", as.name,
                           FormatSigma(as, est.sigma[i]), FormatSigma(as, limit)));
      }
    }
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

}  // namespace turncal
