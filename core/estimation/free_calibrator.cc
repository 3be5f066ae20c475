#include "core/estimation/free_calibrator.h"

#include "core/estimation/free_bias.h"
#include "core/estimation/free_drift.h"
#include "core/estimation/free_noise_reference.h"

#include <ceres/ceres.h>
#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/SVD>
#include <algorithm>
#include <boost/math/special_functions/beta.hpp>
#include <boost/math/special_functions/gamma.hpp>
#include <cmath>
#include <memory>
#include <optional>
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
  if (!(disturbance_sigmas >= 0) || !(max_disturbed_share >= 0 && max_disturbed_share <= 1) ||
      !(max_field_wander > 1)) {
    return fail(
        "the disturbance's limits must be sigmas >= 0, a share in [0, 1] and a wander above 1");
  }
  if (!(max_norm_bias_sigmas > 0))
    return fail("the largest second-order bias must be above 0 sigma");
  if (!(correlation_min_lag_one >= 0 && correlation_min_lag_one < 1) || !(correlation_sigmas > 0)) {
    return fail("the correlation's threshold must be a lag-one in [0, 1) and sigmas above 0");
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

namespace {

// The named triads a free model's intervals may carry.
constexpr SensorKind kTriads[] = {SensorKind::kAccelerometer, SensorKind::kGyroscope,
                                  SensorKind::kMagnetometer};

// CalibrateFree's steps, in the order Run takes them (the shape of Ceres' TrustRegionMinimizer):
// the start, the drift's reference window, the solve re-whitened at each pass' result, the terms
// at the solution, rank and covariance, chi^2 and the fit check, the undetermined and weak
// parameters, the coverage and misfits, and the gate.
class FreeCalibration {
 public:
  FreeCalibration(const FreeModel& model, const FreeData& data,
                  const FreeCalibratorOptions& options, bool whiten)
      : model_(model),
        data_(data),
        options_(options),
        whiten_(whiten),
        est_(out_.estimate),
        n_(model.num_parameters()),
        upstream_(data.upstream_theta) {}

  FreeEstimate Run() {
    est_.model = model_.name();
    est_.parameters = model_.parameters();
    out_.relative_scale =
        model_.sensor() == SensorKind::kMagnetometer && !(data_.context.field_magnitude > 0);
    out_.intervals = CountIntervals();
    for (const auto& iv : data_.intervals)
      out_.motion_points += iv.in_motion && iv.mag && model_.Needs(SensorKind::kMagnetometer);
    est_.poses = out_.intervals;
    if (!model_.Start(data_, &theta_, &est_.error)) return std::move(out_);
    ChooseDrifts();
    for (int pass = 0; pass < options_.passes; ++pass) {
      if (!SolvePass(pass > 0)) return std::move(out_);
    }
    if (out_.correlation.whitened) {
      est_.warnings.push_back(fmt::format(
          "the noise of the values in motion correlates from one to the next ({:.2f} over {} "
          "pairs, {:.3g} ms apart: a filter in the magnetometer?): whitened together as "
          "exp(-dt / {:.3g} ms)",
          out_.correlation.lag_one, out_.correlation.pairs, 1e3 * out_.correlation.spacing_s,
          1e3 * out_.correlation.tau_s));
    }
    // The bias is worked out at the least-squares solution (with the terms and their whitener
    // evaluated there), and the fit is checked there (chi^2's distribution is the minimum's); the
    // estimate then moves by it.
    if (!EvaluateAtSolution()) return std::move(out_);
    const std::optional<Eigen::VectorXd> norm_bias = NormBias();
    RankAndCovariance();
    if (norm_bias) RemoveNormBias(*norm_bias);
    CheckFit();
    est_.covariance = cov_;
    est_.sigma = cov_.diagonal().cwiseMax(0).cwiseSqrt();
    NameUndeterminedAndWeak();
    MeasureCoverageAndMisfits();
    ApplyGate();
    return std::move(out_);
  }

 private:
  // The static intervals that carry every triad the model needs.
  int CountIntervals() const {
    int count = 0;
    for (const auto& iv : data_.intervals) {
      bool has = true;
      for (SensorKind k : kTriads) {
        const bool present = k == SensorKind::kAccelerometer ? iv.acc.has_value()
                             : k == SensorKind::kGyroscope   ? iv.gyr.has_value()
                                                             : iv.mag.has_value();
        if (model_.Needs(k) && !present) has = false;
      }
      count += has;
    }
    return count;
  }

  // The drift of the triads whose bias the model carries, and the reference window: the latest
  // interval's (on the sensor's clock; the bias parameters are then the bias over it).
  // Every triad with a drift model: with the model's bias column for it, or none (its drift
  // still reaches terms through their extra_drift: gyro9's accelerometer). The terms are
  // whitened together when a drift correlates them or they share noise.
  void ChooseDrifts() {
    for (SensorKind kind : kTriads) {
      const BiasDrift& d = kind == SensorKind::kAccelerometer  ? data_.context.acc_drift
                           : kind == SensorKind::kMagnetometer ? data_.context.mag_drift
                                                               : data_.context.gyr_drift;
      if (!d.enabled() || !model_.Needs(kind)) continue;
      int column = -1;
      for (const auto& [k, c] : model_.BiasColumns()) {
        if (k == kind) column = c;
      }
      drifts_.push_back({kind, column, d});
    }
    const FreeInterval* latest = nullptr;
    for (const auto& iv : data_.intervals) {
      // Samples in motion are only the magnetometer models' data (core/estimation/free_motion.h).
      if (iv.in_motion && !model_.Needs(SensorKind::kMagnetometer)) continue;
      origin_s_ = std::min(origin_s_, iv.sensor_start_s());
      if (!latest || iv.sensor_end_s() > latest->sensor_end_s()) latest = &iv;
    }
    if (!drifts_.empty() && latest) {
      reference_ = TimeWindow{latest->sensor_start_s(), latest->sensor_end_s()};
      out_.bias_window = reference_;
      out_.bias_window_host = TimeWindow{latest->t_start_s, latest->t_end_s};
    } else {
      drifts_.clear();
    }
    correlated_by_drift_ = !drifts_.empty();
    for (const auto& t : model_.Terms(data_, theta_)) correlated_by_drift_ |= !t.shared.empty();
    joint_ = correlated_by_drift_;
  }

  // The values in motion's correlation from one to the next in `terms` at theta_ (each whitened
  // by its own noise); taken into the whitening when beyond the threshold.
  void MeasureCorrelation(const std::vector<FreeTerm>& terms) {
    if (out_.motion_points < 20) return;
    const CorrelatedChain chain = MotionChain(terms, data_, 0.0);
    const Evaluated e = Evaluate(terms, theta_, upstream_, nullptr);
    out_.correlation =
        MeasureMotionCorrelation(ChainResiduals(chain, e.r), options_.correlation_min_lag_one,
                                 options_.correlation_sigmas, n_);
    out_.correlation.whitened = whiten_ && out_.correlation.correlated();
    joint_ = correlated_by_drift_ || out_.correlation.whitened;
  }

  // W for `terms` at `at` (the origin of time moves to the earliest term's start).
  Eigen::MatrixXd Whitener(const std::vector<FreeTerm>& terms, const Eigen::VectorXd& at) {
    const CorrelatedChain chain =
        MotionChain(terms, data_, out_.correlation.whitened ? out_.correlation.tau_s : 0.0);
    if (!correlated_by_drift_) {
      int m = 0;
      for (const auto& t : terms) m += t.cost->num_residuals();
      return ChainWhitener(m, chain);
    }
    const Evaluated e = Evaluate(terms, at, upstream_, nullptr);
    for (const auto& term : terms) origin_s_ = std::min(origin_s_, term.window.t0_s);
    return FreeDriftWhitener(terms, e.J, drifts_, reference_, origin_s_,
                             chain.tau_s > 0 ? &chain : nullptr);
  }

  // One solve with the terms whitened at theta_; false (est_.error says why) when it fails.
  // With `measure`, the correlation of the values in motion is measured at theta_ first.
  bool SolvePass(bool measure) {
    terms_ = model_.Terms(data_, theta_);
    if (terms_.empty()) {
      est_.error = fmt::format("{}: the intervals give no residuals", model_.name());
      return false;
    }
    if (measure) MeasureCorrelation(terms_);
    ceres::Problem::Options po;
    po.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    ceres::Problem problem(po);
    Eigen::VectorXd up = upstream_;
    if (joint_) {
      stacked_ = std::make_unique<StackedFreeCost>(terms_, Whitener(terms_, theta_),
                                                   model_.num_parameters(),
                                                   static_cast<int>(upstream_.size()));
      if (stacked_->uses_upstream()) {
        problem.AddResidualBlock(stacked_.get(), nullptr, theta_.data(), up.data());
      } else {
        problem.AddResidualBlock(stacked_.get(), nullptr, theta_.data());
      }
    } else {
      for (const auto& t : terms_) {
        if (t.upstream) {
          problem.AddResidualBlock(t.cost.get(), nullptr, theta_.data(), up.data());
        } else {
          problem.AddResidualBlock(t.cost.get(), nullptr, theta_.data());
        }
      }
    }
    if (up.size() > 0 && problem.HasParameterBlock(up.data())) {
      problem.SetParameterBlockConstant(up.data());
    }
    ceres::Solver::Options so;
    so.linear_solver_type = ceres::DENSE_QR;
    so.max_num_iterations = options_.max_iterations;
    so.function_tolerance = 1e-12;
    so.gradient_tolerance = 1e-14;
    so.parameter_tolerance = 1e-12;
    so.num_threads = 1;
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem, &summary);
    est_.iterations += static_cast<int>(summary.iterations.size());
    est_.termination = ceres::TerminationTypeToString(summary.termination_type);
    est_.solve_time_s += summary.total_time_in_seconds;
    if (!summary.IsSolutionUsable() || !theta_.allFinite()) {
      est_.error = fmt::format("{}: the solve failed ({})", model_.name(), summary.message);
      return false;
    }
    return true;
  }

  // The norm models' second-order bias from the values' noise at theta_ (core/estimation/
  // free_bias.h); nullopt when not removed.
  // Whitened together (a drift, a correlation between the values), the bias is the generalised
  // fit's: its weights W'W (the whitener EvaluateAtSolution built) and the values' noise
  // correlation.
  std::optional<Eigen::VectorXd> NormBias() const {
    if (!options_.remove_norm_bias) return std::nullopt;
    if (!joint_) return NormFitBias(model_, data_, theta_);
    NormBiasCorrelation correlated;
    correlated.weight = whitener_.transpose() * whitener_;
    correlated.noise = Eigen::MatrixXd::Identity(whitener_.rows(), whitener_.cols());
    if (out_.correlation.whitened) {
      AddChainCovariance(MotionChain(terms_, data_, out_.correlation.tau_s), &correlated.noise);
    }
    return NormFitBias(model_, data_, theta_, &correlated);
  }

  // The estimate less `bias`, kept in the estimate with its size in the estimate's own metric:
  // |J b| with J whitened at the fit, the chi^2 the move adds (before any inflation).
  void RemoveNormBias(const Eigen::VectorXd& bias) {
    out_.norm_bias = bias;
    out_.norm_bias_sigmas = (ev_.J * bias).norm();
    theta_ -= bias;
    est_.theta = theta_;
  }

  // The terms at the solution (with a joint whitening: the innovations, the terms whitened
  // together); false when a residual is not finite.
  bool EvaluateAtSolution() {
    terms_ = model_.Terms(data_, theta_);
    ev_ = Evaluate(terms_, theta_, upstream_, &out_.terms);
    if (joint_ && ev_.r.allFinite()) {
      whitener_ = Whitener(terms_, theta_);
      ev_.r = whitener_ * ev_.r;
      ev_.J = whitener_ * ev_.J;
      if (ev_.Ju.cols() > 0) ev_.Ju = whitener_ * ev_.Ju;
      int row = 0;
      for (auto& t : out_.terms) {
        const auto k = t.whitened.size();
        t.whitened = ev_.r.segment(row, k);
        row += static_cast<int>(k);
      }
    }
    if (!ev_.r.allFinite()) {
      est_.error = fmt::format("{}: a residual is not finite at the solution", model_.name());
      return false;
    }
    out_.residuals = static_cast<int>(ev_.r.size());
    est_.theta = theta_;
    est_.ok = true;
    return true;
  }

  // Rank and covariance in scaled units, with the upstream estimate's part (Murphy and Topel).
  void RankAndCovariance() {
    const Eigen::VectorXd scales = model_.Scales(data_, theta_);
    out_.analysis = AnalyzeRank(ev_.J, model_.parameters(), scales, options_.observability);
    est_.rank = out_.analysis.rank;
    est_.condition = out_.analysis.condition;
    const Eigen::MatrixXd Js = ev_.J * scales.asDiagonal();
    with_upstream_ = upstream_.size() > 0 && data_.upstream_covariance.rows() == upstream_.size() &&
                     data_.upstream_covariance.allFinite();
    svd_.emplace(
        Js, with_upstream_ ? (Eigen::ComputeFullU | Eigen::ComputeFullV) : Eigen::ComputeFullV);
    const Eigen::VectorXd& s = svd_->singularValues();
    Eigen::MatrixXd pinv = Eigen::MatrixXd::Zero(n_, n_);
    for (int i = 0; i < est_.rank && i < s.size(); ++i) {
      pinv += svd_->matrixV().col(i) * svd_->matrixV().col(i).transpose() / (s[i] * s[i]);
    }
    cov_ = scales.asDiagonal() * pinv * scales.asDiagonal();
    if (with_upstream_) {
      const Eigen::MatrixXd G = cov_ * ev_.J.transpose() * ev_.Ju;  // d theta / d upstream
      cov_ += G * data_.upstream_covariance * G.transpose();
    }
  }

  // chi^2, the two-sided fit check and, when chi^2 is too large, the covariance's inflation.
  void CheckFit() {
    est_.chi2 = ev_.r.squaredNorm();
    if (with_upstream_ && est_.rank < ev_.r.size()) {
      // The upstream estimate's error is in every residual too: in the residuals' space, left
      // after the fit (N, the complement of J's columns), they have the covariance
      // N^T (I + A C_u A^T) N, A = d r / d upstream. chi^2 against it (without it, a noisy
      // upstream read as misfit: gyro9 on an accelerometer with 8 mg per sample had chi^2/dof
      // 1.09).
      const Eigen::MatrixXd N = svd_->matrixU().rightCols(ev_.r.size() - est_.rank);
      const Eigen::MatrixXd NA = N.transpose() * ev_.Ju;
      Eigen::MatrixXd C = NA * data_.upstream_covariance * NA.transpose();
      C.diagonal().array() += 1.0;
      const Eigen::VectorXd y = N.transpose() * ev_.r;
      const Eigen::LLT<Eigen::MatrixXd> llt(C);
      if (llt.info() == Eigen::Success) est_.chi2 = y.dot(llt.solve(y));
    }
    est_.dof = out_.residuals - est_.rank;
    FitCheck& fit = est_.fit;
    fit.chi2 = est_.chi2;
    fit.dof = est_.dof;
    const MotionNoiseReference noise =
        est_.dof > 0 && 2 * out_.motion_points > out_.intervals
            ? MotionNoiseReferenceFor(model_, data_, theta_, options_.motion_noise_dof)
            : MotionNoiseReference{};
    const double nu = noise.dof;
    // Whitened with a correlation measured from the same residuals, chi^2 varies as their plain
    // sum of squares does: fewer degrees of freedom (ChainChi2DofShare).
    if (out_.correlation.whitened) {
      fit.dof_share = ChainChi2DofShare(MotionChain(terms_, data_, out_.correlation.tau_s),
                                        static_cast<int>(ev_.r.size()));
    }
    const double d1 = est_.dof * fit.dof_share, x = est_.dof > 0 ? est_.chi2 / est_.dof : 0.0;
    if (est_.dof > 0 && std::isfinite(nu) && nu > 0) {
      // F = (chi^2 / dof) / scale against the noise's own chi^2_nu / nu: P(F > y) =
      // I_{nu / (nu + d1 y)}(nu / 2, d1 / 2).
      const double y = x / noise.scale;
      fit.p_upper = boost::math::ibeta(nu / 2, d1 / 2, nu / (nu + d1 * y));
      fit.p_lower = boost::math::ibetac(nu / 2, d1 / 2, nu / (nu + d1 * y));
      fit.noise_dof = nu;
      fit.noise_scale = noise.scale;
    } else if (est_.dof > 0) {
      fit.p_upper = boost::math::gamma_q(d1 / 2, d1 * x / 2);
      fit.p_lower = boost::math::gamma_p(d1 / 2, d1 * x / 2);
    }
    est_.p_value = fit.p_upper;
    for (const auto& t : out_.terms) {
      const double normalized = std::sqrt(t.whitened.squaredNorm() / t.whitened.size());
      if (normalized > fit.worst_normalized) {
        fit.worst_normalized = normalized;
        fit.worst_pose = t.interval;
      }
    }
    if (est_.dof > 0 && fit.p_upper < options_.chi2_inflation_p_value) {
      fit.verdict = FitVerdict::kTooLarge;
      fit.cause =
          fit.worst_normalized > options_.outlier_threshold
              ? fmt::format(
                    "interval {} has the largest residual ({:.1f} sigma): it may not have "
                    "been still, or the model does not fit it",
                    fit.worst_pose, fit.worst_normalized)
              : "the intervals' noise is larger than their own scatter says (bias instability, "
                "a hand's placement), or the model does not fit";
      if (options_.inflate_covariance_by_chi2) {
        est_.covariance_scale = est_.chi2 / est_.dof;
        cov_ *= est_.covariance_scale;
        est_.warnings.push_back(
            fmt::format("chi2/dof = {:.2f} (p = {:.2g}): covariance inflated by that factor",
                        est_.covariance_scale, fit.p_upper));
      }
    } else if (est_.dof > 0 && fit.p_lower < options_.chi2_inflation_p_value) {
      fit.verdict = FitVerdict::kTooSmall;
      fit.cause = "the residuals are smaller than the intervals' noise says";
    }
  }

  // The parameters in a null direction (sigma infinite) and in a direction weaker than the gate
  // allows, in the model's order.
  void NameUndeterminedAndWeak() {
    std::set<std::string> undetermined, weak;
    for (const auto& d : out_.analysis.null) {
      for (int i = 0; i < n_; ++i) {
        if (std::abs(d.scaled[i]) > options_.observability.involvement) {
          est_.sigma[i] = INFINITY;
          undetermined.insert(model_.parameters()[i].name);
        }
      }
    }
    for (const auto& d : out_.analysis.weak) {
      if (d.relative_singular_value >= options_.min_relative_singular) continue;
      for (const auto& name : d.involved) weak.insert(name);
    }
    for (const auto& p : model_.parameters()) {
      if (undetermined.count(p.name)) out_.undetermined.push_back(p.name);
      if (weak.count(p.name) && !undetermined.count(p.name)) out_.weak.push_back(p.name);
    }
  }

  // Coverage of the corrected triad's directions; the misfits before and after.
  void MeasureCoverageAndMisfits() {
    for (const auto& iv : data_.intervals) {
      const Eigen::Vector3d d = model_.Direction(data_, theta_, iv);
      if (d.squaredNorm() > 0) out_.directions.push_back(d);
    }
    out_.coverage = CoverageOf(out_.directions);
    out_.gap = LargestGap(out_.coverage);
    out_.before = SummarizeMisfits(model_.Misfits(data_, model_.Identity(data_)));
    out_.after = SummarizeMisfits(model_.Misfits(data_, theta_));
  }

  void Refuse(std::string why) { out_.gate_reasons.push_back(std::move(why)); }

  static std::string Join(const std::vector<std::string>& v) {
    std::string text;
    for (const auto& x : v) text += (text.empty() ? "" : ", ") + x;
    return text;
  }

  // The gate: rank and weak directions, coverage, the station's precision, the sigma limits.
  void ApplyGate() {
    if (est_.rank < n_) {
      Refuse(fmt::format("rank {} of {}: the data do not determine {}", est_.rank, n_,
                         Join(out_.undetermined)));
    } else if (!out_.weak.empty()) {
      Refuse(fmt::format(
          "the weakest direction ({:.2g} of the strongest) involves {}",
          out_.analysis.weak.empty() ? 0.0 : out_.analysis.weak.back().relative_singular_value,
          Join(out_.weak)));
    }
    if (const auto [name, sigmas] = LargestNormBias(out_); sigmas > options_.max_norm_bias_sigmas) {
      Refuse(fmt::format(
          "the second-order bias removed from {} is {:.2f} sigma: the coverage is too weak for "
          "the sigma to hold (a linear sigma needs the bias well within it); turn it further",
          name, sigmas));
    }
    if (options_.min_coverage > 0 && out_.coverage.fraction() < options_.min_coverage) {
      Refuse(fmt::format("coverage {:.1f} % of the sphere is below the {:.1f} % required",
                         100 * out_.coverage.fraction(), 100 * options_.min_coverage));
    }
    if (options_.precision) ApplyPrecisionGate(*options_.precision);
    for (const auto& [name, limit] : options_.max_sigma) {
      const int i = model_.index_of(name);
      if (i >= 0 && !(est_.sigma[i] <= limit)) {
        Refuse(fmt::format("sigma of {} is {:.3g}, above its limit {:.3g}", name, est_.sigma[i],
                           limit));
      }
    }
    out_.gate_passed = out_.gate_reasons.empty();
  }

  // The station's gate: redundancy, the fit check's p-value, each parameter's tolerance.
  void ApplyPrecisionGate(const GateOptions& g) {
    if (est_.dof < g.min_dof) {
      Refuse(fmt::format("{} redundant equations: the fit check needs at least {}", est_.dof,
                         g.min_dof));
    } else if (est_.p_value < g.min_p_value) {
      Refuse(fmt::format(
          "chi2/dof {:.2f} (p {:.2g}, below {:.2g}): {}", est_.dof > 0 ? est_.chi2 / est_.dof : 0.0,
          est_.p_value, g.min_p_value,
          est_.fit.cause.empty() ? "the noise model or the model does not fit" : est_.fit.cause));
    }
    for (int i = 0; i < n_; ++i) {
      ParameterInfo as;
      const double limit = FreeToleranceFor(model_.parameters()[i], g, &as);
      if (limit > 0 && std::isfinite(est_.sigma[i]) && !(est_.sigma[i] <= limit)) {
        Refuse(fmt::format("{}: sigma {} exceeds the tolerance {}", as.name,
                           FormatSigma(as, est_.sigma[i]), FormatSigma(as, limit)));
      }
    }
  }

  const FreeModel& model_;
  const FreeData& data_;
  const FreeCalibratorOptions& options_;
  const bool whiten_;  // the values in motion whitened together when measured correlated
  FreeEstimate out_;
  Estimate& est_;
  const int n_;
  Eigen::VectorXd theta_;
  const Eigen::VectorXd upstream_;
  // The drift's whitening: the triads, the reference window, the origin of time.
  std::vector<FreeDriftTriad> drifts_;
  TimeWindow reference_;
  double origin_s_ = INFINITY;
  bool joint_ = false;
  bool correlated_by_drift_ = false;  // by a triad's drift or noise terms share
  // The solve's terms (the stacked cost refers to them) and the terms at the solution.
  std::vector<FreeTerm> terms_;
  Eigen::MatrixXd whitener_;  // the terms whitened together at the solution (joint_)
  std::unique_ptr<StackedFreeCost> stacked_;
  Evaluated ev_;
  bool with_upstream_ = false;
  std::optional<Eigen::JacobiSVD<Eigen::MatrixXd>> svd_;
  Eigen::MatrixXd cov_;
};

}  // namespace

std::pair<std::string, double> LargestNormBias(const FreeEstimate& estimate) {
  const Estimate& e = estimate.estimate;
  std::pair<std::string, double> out{"", 0.0};
  if (estimate.norm_bias.size() != e.sigma.size()) return out;
  for (Eigen::Index i = 0; i < e.sigma.size(); ++i) {
    const double ratio = std::abs(estimate.norm_bias[i]) / e.sigma[i];
    if (std::isfinite(ratio) && ratio > out.second &&
        i < static_cast<Eigen::Index>(e.parameters.size())) {
      out = {e.parameters[static_cast<std::size_t>(i)].name, ratio};
    }
  }
  return out;
}

FreeEstimate CalibrateFree(const FreeModel& model, const FreeData& data,
                           const FreeCalibratorOptions& options) {
  return LeaveOutDisturbedMotion(model, data, options, [&](const FreeData& d, bool whiten) {
    return FreeCalibration(model, d, options, whiten).Run();
  });
}

}  // namespace turncal
