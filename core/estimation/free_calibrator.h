#pragma once
// A calibration without known poses (issue 22): one free model (core/modeling/free_model.h) fitted
// to the static intervals of a tumble by maximum likelihood, with the covariance from the Fisher
// information, the chi^2 fit check, the data-level rank with named weak directions, the tumble's
// spatial coverage and a gate.
//
// The terms are whitened at a parameter point, so the solve is repeated with the terms whitened
// at its result (three passes; the weights of norm residuals move with the gains by their
// relative error only). A model built on another's estimate (gyro9 on accel9) holds that estimate
// fixed and adds its covariance through the sensitivity of the terms to it (the two-step
// estimator's covariance, Murphy and Topel): C = A^-1 + A^-1 J^T J_u C_u J_u^T J A^-1, A = J^T J.
// The upstream's noise and this model's are independent to first order: accel9 uses the radial
// part of each interval's mean, gyro9's direction terms the part across it.

#include <Eigen/Core>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "core/analysis/observability.h"
#include "core/analysis/publish_gate.h"
#include "core/analysis/sphere_coverage.h"
#include "core/estimation/calibrator.h"
#include "core/estimation/free_correlation.h"
#include "core/estimation/free_disturbance.h"
#include "core/modeling/free_model.h"

namespace turncal {

struct FreeCalibratorOptions {
  int passes = 3;
  int max_iterations = 200;
  // chi^2 above its degrees of freedom at this upper-tail p inflates the covariance by chi^2/dof
  // (as the pose calibrator does; the estimate says so).
  bool inflate_covariance_by_chi2 = true;
  double chi2_inflation_p_value = 0.01;
  // The degrees of freedom of the magnetometer's per-sample noise that the samples in motion are
  // weighed with (MotionPoints::sigma_dof; infinite: known). Finite, and the samples in motion
  // the most of the terms, the fit check is the F test of the residuals' variance against that
  // noise's, F(dof, nu) with nu this per axis times up to 3 (the norm residuals average the
  // axes' estimates as the rotation turns each along the field), not the chi^2: a sigma from a
  // noise meter's second of a 50-Hz magnetometer is 10 % uncertain, and the chi^2 against it
  // piled its p-values at both ends (200 hand rotations with a 4-s pause: 91 in the lowest
  // tenth, 30 in the highest).
  double motion_noise_dof = std::numeric_limits<double>::infinity();
  double outlier_threshold = 4.0;
  // The magnetometer's samples in motion whose field magnitude departs from the fit beyond this
  // many robust sigmas (or the count's Bonferroni bound, when larger) are left out as disturbed
  // and the fit repeated; more than max_disturbed_share of them disturbed refuses the
  // calibration, and departures scattering more than max_field_wander times their step noise
  // refuse it too (core/estimation/free_disturbance.h). 0: none left out.
  double disturbance_sigmas = 5.0;
  double max_disturbed_share = 0.1;
  double max_field_wander = 5.0;
  // The values in motion whitened together when their residuals' lag-one correlation at the fit
  // exceeds max(correlation_min_lag_one, correlation_sigmas / sqrt(pairs))
  // (core/estimation/free_correlation.h: a magnetometer's filter correlates its noise); false:
  // always taken as independent.
  bool whiten_correlated_motion = true;
  double correlation_min_lag_one = 0.1;
  double correlation_sigmas = 3.5;
  // Remove the norm models' second-order bias from the values' noise (core/estimation/free_bias.h:
  // half a sigma on the gains where the coverage is weak); false: the plain least squares.
  bool remove_norm_bias = true;
  // ... and refuse when it was larger than this many sigmas of its parameter: the expansion, and
  // with it the sigma, no longer holds (1: in 200 tumbles the one run beyond was refused anyway).
  double max_norm_bias_sigmas = 1.0;
  ObservabilityOptions observability;

  // The gate: the model's parameters all determined (full rank), the weakest direction's
  // relative singular value above this, and the coverage above min_coverage (a share of the 576
  // bins; 0 checks none).
  double min_relative_singular = 1e-3;
  double min_coverage = 0.0;
  // A parameter's sigma above this (in its display unit's terms: the gate's per-parameter limit
  // in parameter units; empty: none) refuses too.
  std::vector<std::pair<std::string, double>> max_sigma;
  // The station's gate (turncald's free pose source, [gate]): every sensor parameter's sigma
  // within its tolerance (FreeToleranceFor), at least min_dof redundant equations and the
  // chi^2's upper-tail p-value at least min_p_value. Unset (turncal free): none of these.
  std::optional<GateOptions> precision;

  bool IsValid(std::string* error) const;
};

struct FreeTermResidual {
  int interval = -1;
  std::string kind;
  Eigen::VectorXd whitened;  // 1 (norm, dip), 2 (direction) or 3 (rest) entries
};

// The misfits of one kind (FreeModel::Misfits) over the intervals: RMS and largest magnitude.
struct MisfitFigure {
  std::string kind;
  int count = 0;
  double rms = 0.0, max_abs = 0.0;
};
std::vector<MisfitFigure> SummarizeMisfits(const std::vector<FreeModel::Misfit>& misfits);

struct FreeEstimate {
  // Parameters, theta, covariance (with the upstream's part and any chi^2 inflation), sigma (inf
  // for a parameter in a null direction), rank, condition, chi^2, dof, p-value, fit check,
  // warnings. `poses` counts the intervals used, `residuals` is empty (see terms).
  Estimate estimate;
  RankAnalysis analysis;  // of the whitened Jacobian, columns scaled by FreeModel::Scales
  std::vector<FreeTermResidual> terms;
  int intervals = 0;      // static intervals carrying the model's triads (and samples in motion)
  int motion_points = 0;  // of them, the magnetometer's samples in motion (issue 37)
  int residuals = 0;      // scalar residuals
  SphereCoverage coverage;
  CoverageGap gap;  // the largest region of the coverage without a direction
  std::vector<Eigen::Vector3d> directions;  // per interval used: the corrected triad's mean
  // Parameters that take part in a null direction (not determined at all) or a weak one.
  std::vector<std::string> undetermined, weak;
  bool gate_passed = false;
  std::vector<std::string> gate_reasons;  // why the gate refused, one line each
  bool relative_scale = false;            // a magnetometer model without the field's magnitude
  // With a drift model (FreeContext's *_drift): the latest interval's window, which the bias
  // parameters are the bias over, on the sensor's clock and on the host's.
  std::optional<TimeWindow> bias_window, bias_window_host;
  // What the raw triad leaves (FreeModel::Identity) and what the calibration leaves, per kind.
  std::vector<MisfitFigure> before, after;
  // The samples in motion left out as disturbed, when any (the fit is the one without them).
  std::optional<FieldDisturbance> disturbance;
  // With samples in motion: their departures' robust scatter over their step noise at the fit
  // (1 for white noise; FreeCalibratorOptions::max_field_wander); 0 when not judged.
  double field_wander = 0.0;
  // With samples in motion: their noise's measured correlation from one value to the next, and
  // whether (tau_s > 0) they were whitened together.
  MotionCorrelation correlation;
  // The second-order bias from the values' noise, removed from the estimate (parameter units;
  // empty when not computed: FreeCalibratorOptions::remove_norm_bias, a model without norm terms).
  Eigen::VectorXd norm_bias;
  // Its size in the estimate's own metric, sqrt(b' C^-1 b) (C the covariance before any chi^2
  // inflation; at least the largest |b_i| / sigma_i): the chi^2 the move adds is its square.
  double norm_bias_sigmas = 0.0;
};

// The norm misfit's RMS after the fit in per cent of the magnitude it is fitted to (the field's,
// 1 for a relative scale, or gravity's), the "fit error" of the vendors' tools: the magnetometer's
// ("mag norm", or "norm" of a magnetometer model) or the accelerometer's; NaN when `fe` has none.
double FitErrorPercent(const FreeEstimate& fe, SensorKind model_sensor, SensorKind triad,
                       const FreeContext& context);

// Fits `model` to `data`. !estimate.ok with a message when the model cannot start (too few
// intervals, no upstream estimate) or the solve fails.
// The parameter whose removed second-order bias (FreeEstimate::norm_bias) is the largest in sigmas,
// and how many; ("", 0) when none was removed.
std::pair<std::string, double> LargestNormBias(const FreeEstimate& estimate);

FreeEstimate CalibrateFree(const FreeModel& model, const FreeData& data,
                           const FreeCalibratorOptions& options);

// The whitened Jacobian of `model`'s terms over `data` at theta (rows: the terms' residuals in
// order; columns: the model's parameters), for the analyses that weigh hypothetical intervals.
Eigen::MatrixXd FreeJacobian(const FreeModel& model, const FreeData& data,
                             const Eigen::VectorXd& theta);

// One model's estimate among several (CalibrateFreeModels), with what was chosen and why.
struct FreeModelResult {
  std::string requested;  // as asked ("magellipsoid")
  std::string model;      // as fitted ("magsphere" when the ellipsoid could not be carried)
  std::string note;       // why another model was fitted, or why none; empty otherwise
  FreeEstimate estimate;
};

// Fits each of `models` in order to `intervals`, each model's upstream (accel9 for gyro9) fitted
// first when it is not in the list before it. A magellipsoid the data cannot carry (refused for
// rank or a weak direction) falls back to magsphere with the reason in `note`. Models unknown by
// name fail with a message (nothing fitted).
bool CalibrateFreeModels(const std::vector<std::string>& models,
                         const std::vector<FreeInterval>& intervals, const FreeContext& context,
                         const FreeCalibratorOptions& options, std::vector<FreeModelResult>* out,
                         std::string* error);

// The models a set of intervals can feed: accel9 with the accelerometer, gyro9 with the gyro and
// moves, magellipsoid with the magnetometer, accmag with both of the latter two.
std::vector<std::string> DefaultFreeModels(const std::vector<FreeInterval>& intervals);

}  // namespace turncal
