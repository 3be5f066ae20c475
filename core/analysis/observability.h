#pragma once
// Observability (MODELS.md "Observability"): the seed's structural test, the data-level test that
// matters for a given set of poses, and the diversity of those poses.
//
// Every rank below is the numerical rank of a Jacobian whose columns are scaled by the
// parameters' nominal sizes (ParameterScale), so a singular value is the effect of a relative
// change of a parameter. A singular value counts as zero when it is below `rank_tolerance` times
// the largest. The exact symmetries of the models (mag22's gauge, a single turning axis) give
// singular values at the level of rounding, ~1e-15 relative; the weakest genuine direction in any
// model here (accel13's beta at sensor-grade noise) is ~1e-3. The default 1e-9 sits between them
// with six orders of magnitude to spare on either side.

#include <Eigen/Core>
#include <random>
#include <string>
#include <vector>

#include "core/estimation/pose_record.h"
#include "core/modeling/measurement_model.h"

namespace turncal {

struct ObservabilityOptions {
  double rank_tolerance = 1e-9;
  // Directions with relative singular value below this (and above rank_tolerance) are reported
  // as weak; the weakest direction is always reported.
  double weak_ratio = 1e-2;
  // A parameter takes part in a direction when its coefficient in scaled units exceeds this.
  double involvement = 0.05;

  bool IsValid(std::string* error) const;
};

// The size against which a parameter is judged: 1 for scale factors and gains (the size of 1+S
// or of G's entries), 1 rad for angles, the excitation's magnitude for biases (|f_NED| or
// |B_NED|).
double ParameterScale(const ParameterInfo& parameter, const MeasurementModel& model);
Eigen::VectorXd ParameterScales(const MeasurementModel& model);

// A direction in parameter space, written as a combination of named parameters.
struct NamedDirection {
  // Unit vector in the parameters' own units: moving theta along it by a small amount changes
  // the predictions by singular_value times that amount (scaled units).
  Eigen::VectorXd coefficients;
  // Unit vector in scaled units (parameter / ParameterScale), the one the rank test uses.
  Eigen::VectorXd scaled;
  double relative_singular_value = 0.0;
  // Parameters whose scaled coefficient exceeds ObservabilityOptions::involvement, largest first.
  std::vector<std::string> involved;
  // "0.71·k11 + 0.70·k22 − 0.07·dBz" over the coefficients above 0.01 in magnitude.
  std::string text;
};

// Rank analysis of one Jacobian (rows: equations, columns: the model's parameters).
struct RankAnalysis {
  int rank = 0;
  int columns = 0;
  double condition = 0.0;             // s_max / s_min of the scaled Jacobian (inf if singular)
  Eigen::VectorXd relative_singular;  // s_i / s_max, descending
  std::vector<NamedDirection> null;   // below rank_tolerance
  std::vector<NamedDirection> weak;   // below weak_ratio, or the weakest one
};

RankAnalysis AnalyzeRank(const Eigen::MatrixXd& jacobian, const MeasurementModel& model,
                         const ObservabilityOptions& options);
// The same for any parameter list with the sizes its columns are scaled by (the free models of
// core/modeling/free_model.h).
RankAnalysis AnalyzeRank(const Eigen::MatrixXd& jacobian, const std::vector<ParameterInfo>& params,
                         const Eigen::VectorXd& scales, const ObservabilityOptions& options);

// The seed's test: the Jacobian of theta -> theta^e at `theta`.
struct StructuralReport {
  std::string model;
  int params = 0;
  int extended = 0;  // entries of theta^e
  Eigen::VectorXd theta;
  RankAnalysis analysis;
};

// A generic parameter point: nominal plus a 10 % (of ParameterScale) Gaussian perturbation of
// every parameter, beta uniform on [-pi, pi). Generic points avoid accidental symmetries (mag22 at
// K_ = I has a third null direction, see core/modeling/mag22_gauge.h).
Eigen::VectorXd GenericParameterPoint(const MeasurementModel& model, std::mt19937_64* rng);

StructuralReport AnalyzeStructure(const MeasurementModel& model, const Eigen::VectorXd& theta,
                                  const ObservabilityOptions& options);

// Diversity of the poses themselves, independent of any parameter value: the stacked regressors
// [m'^T 1] of the linear form (MODELS.md) and where "down" points in the table frame q.
struct PoseDiversity {
  int poses = 0;
  int regressor_rank = 0;               // of N x 10 [m'^T 1], columns scaled to unit norm
  double regressor_min_singular = 0.0;  // relative to the largest
  int distinct_down = 0;                // distinct directions of down in q (to 1e-6)
  Eigen::Vector3d down_scatter = Eigen::Vector3d::Zero();  // eigenvalues of mean d d^T, desc
  std::vector<std::string> findings;  // plain-language diagnosis; empty when diverse
};

PoseDiversity AnalyzePoseDiversity(const std::vector<TablePose>& poses,
                                   const Eigen::Vector3d& v_ned,
                                   const ObservabilityOptions& options);

// A parameter with a component above this (scaled units) in a null direction outside the gauge
// is not determined by the data.
inline constexpr double kUndeterminedComponent = 1e-6;

// The model's exact symmetries at theta in parameter units (N x gauge_dimension; mag22's two
// directions of core/modeling/mag22_gauge.h, nothing for the other models).
Eigen::MatrixXd GaugeDirections(const MeasurementModel& model, const Eigen::VectorXd& theta);

// The part of `scaled` (a direction in scaled units) outside the span of the gauge directions.
Eigen::VectorXd OutsideGauge(const MeasurementModel& model, const Eigen::VectorXd& theta,
                             const Eigen::VectorXd& scaled);

// One record's unwhitened Jacobian at theta: the model's prediction's for a pose or rate
// segment, its residual's for a move (WeightedPose::raw_residual).
Jacobian3 RecordJacobian(const MeasurementModel& model, const Eigen::VectorXd& theta,
                         const WeightedPose& record);

// The whitened Jacobian J = Sigma^{-1/2} dr/dtheta over the poses, stacked (3 rows a pose).
Eigen::MatrixXd WhitenedJacobian(const MeasurementModel& model, const Eigen::VectorXd& theta,
                                 const std::vector<WeightedPose>& poses);

// The data-level test at `theta` over the captured (or planned) poses.
struct DataReport {
  std::string model;
  int params = 0;
  int poses = 0;
  int expected_rank = 0;  // params - gauge_dimension
  Eigen::VectorXd theta;
  RankAnalysis analysis;
  Eigen::MatrixXd fisher;  // J^T J, in the parameters' units
  // Cramer-Rao 1 sigma, sqrt(diag(F^+)); in the model's gauge when it has one. Infinity for a
  // parameter that takes part in a null direction outside the gauge.
  Eigen::VectorXd sigma;
  std::string gauge;  // how the gauge directions were fixed, when the model has any
  PoseDiversity diversity;
};

DataReport AnalyzeData(const MeasurementModel& model, const Eigen::VectorXd& theta,
                       const std::vector<WeightedPose>& poses, const ObservabilityOptions& options);

// The same sqrt-information for every planned pose: white noise of density `noise_density`
// averaged over `dwell_s` plus `pose_offset_sigma` on every axis (CalibratorOptions' noise model).
Eigen::Matrix3d ExpectedSqrtInformation(double noise_density, double pose_offset_sigma,
                                        double dwell_s);

}  // namespace turncal
