#include "core/analysis/observability.h"

#include <ceres/cost_function.h>
#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>

#include "core/estimation/calibrator.h"
#include "core/estimation/linear_start.h"
#include "core/modeling/mag22_gauge.h"

namespace turncal {

bool ObservabilityOptions::IsValid(std::string* error) const {
  auto fail = [&](const char* message) {
    if (error) *error = message;
    return false;
  };
  if (!(rank_tolerance > 0 && rank_tolerance < 1)) return fail("rank_tolerance must be in (0, 1)");
  if (!(weak_ratio > rank_tolerance && weak_ratio < 1)) {
    return fail("weak_ratio must be in (rank_tolerance, 1)");
  }
  if (!(involvement > 0 && involvement < 1)) return fail("involvement must be in (0, 1)");
  return true;
}

double ParameterScale(const ParameterInfo& parameter, const MeasurementModel& model) {
  switch (parameter.unit) {
    case ParameterUnit::kScaleFactor:
    case ParameterUnit::kAngle:
      return 1.0;
    case ParameterUnit::kGain:
      return std::max(1.0, std::abs(parameter.nominal));
    case ParameterUnit::kAcceleration:
    case ParameterUnit::kField:
      return model.excitation_ned().norm();
    // A gyroscope's columns: G's are the rates (a rate table's, ~1 rad/s), the bias's the unit,
    // B_g's the specific force (~g): scaled so that each is ~1 rad/s.
    case ParameterUnit::kAngularRate:
      return 1.0;
    case ParameterUnit::kGSensitivity:
      return 1.0 / kStandardGravity_mps2;
    // K2's column is the squared specific force (~g^2): scaled to ~g like the others'.
    case ParameterUnit::kSecondOrder:
      return 1.0 / model.excitation_ned().norm();
  }
  return 1.0;
}

Eigen::VectorXd ParameterScales(const MeasurementModel& model) {
  Eigen::VectorXd d(model.num_parameters());
  for (int i = 0; i < d.size(); ++i) d[i] = ParameterScale(model.parameters()[i], model);
  return d;
}

namespace {

NamedDirection Name(const Eigen::VectorXd& scaled_in, double relative_singular,
                    const std::vector<ParameterInfo>& params, const Eigen::VectorXd& scales,
                    const ObservabilityOptions& options) {
  NamedDirection d;
  Eigen::Index largest = 0;
  scaled_in.cwiseAbs().maxCoeff(&largest);
  d.scaled = scaled_in[largest] < 0 ? Eigen::VectorXd(-scaled_in) : scaled_in;
  d.coefficients = scales.cwiseProduct(d.scaled).normalized();
  d.relative_singular_value = relative_singular;
  std::vector<int> order(params.size());
  for (int i = 0; i < static_cast<int>(order.size()); ++i) order[i] = i;
  std::sort(order.begin(), order.end(),
            [&](int a, int b) { return std::abs(d.scaled[a]) > std::abs(d.scaled[b]); });
  for (int i : order) {
    if (std::abs(d.scaled[i]) > options.involvement) d.involved.push_back(params[i].name);
  }
  std::sort(order.begin(), order.end(), [&](int a, int b) {
    return std::abs(d.coefficients[a]) > std::abs(d.coefficients[b]);
  });
  for (int i : order) {
    const double c = d.coefficients[i];
    if (std::abs(c) < 0.01) break;
    if (d.text.empty()) {
      d.text = fmt::format("{}{:.3g}·{}", c < 0 ? "−" : "", std::abs(c), params[i].name);
    } else {
      d.text += fmt::format(" {} {:.3g}·{}", c < 0 ? "−" : "+", std::abs(c), params[i].name);
    }
  }
  return d;
}

}  // namespace

Eigen::MatrixXd GaugeDirections(const MeasurementModel& model, const Eigen::VectorXd& theta) {
  if (model.gauge_dimension() == 0) return Eigen::MatrixXd(model.num_parameters(), 0);
  return Mag22NullDirections(model, theta);
}

Eigen::VectorXd OutsideGauge(const MeasurementModel& model, const Eigen::VectorXd& theta,
                             const Eigen::VectorXd& scaled) {
  if (model.gauge_dimension() == 0) return scaled;
  const Eigen::MatrixXd gauge =
      ParameterScales(model).cwiseInverse().asDiagonal() * GaugeDirections(model, theta);
  const Eigen::MatrixXd Q =
      gauge.householderQr().householderQ() * Eigen::MatrixXd::Identity(gauge.rows(), gauge.cols());
  return scaled - Q * (Q.transpose() * scaled);
}

RankAnalysis AnalyzeRank(const Eigen::MatrixXd& jacobian, const MeasurementModel& model,
                         const ObservabilityOptions& options) {
  return AnalyzeRank(jacobian, model.parameters(), ParameterScales(model), options);
}

RankAnalysis AnalyzeRank(const Eigen::MatrixXd& jacobian, const std::vector<ParameterInfo>& model,
                         const Eigen::VectorXd& scales, const ObservabilityOptions& options) {
  const int N = static_cast<int>(model.size());
  RankAnalysis out;
  out.columns = N;
  out.relative_singular = Eigen::VectorXd::Zero(N);
  Eigen::MatrixXd V = Eigen::MatrixXd::Identity(N, N);
  if (jacobian.rows() > 0) {
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(jacobian * scales.asDiagonal(), Eigen::ComputeFullV);
    const Eigen::VectorXd& s = svd.singularValues();
    V = svd.matrixV();
    if (s.size() > 0 && s[0] > 0) {
      out.relative_singular.head(s.size()) = s / s[0];
    }
  }
  for (int i = 0; i < N; ++i) out.rank += out.relative_singular[i] > options.rank_tolerance;
  const double smallest = out.relative_singular[N - 1];
  out.condition = smallest > 0 ? 1.0 / smallest : INFINITY;
  for (int i = out.rank; i < N; ++i) {
    out.null.push_back(Name(V.col(i), out.relative_singular[i], model, scales, options));
  }
  for (int i = 0; i < out.rank; ++i) {
    if (out.relative_singular[i] < options.weak_ratio || i == out.rank - 1) {
      out.weak.push_back(Name(V.col(i), out.relative_singular[i], model, scales, options));
    }
  }
  return out;
}

Eigen::VectorXd GenericParameterPoint(const MeasurementModel& model, std::mt19937_64* rng) {
  std::normal_distribution<double> normal(0.0, 0.1);
  std::uniform_real_distribution<double> heading(-M_PI, M_PI);
  Eigen::VectorXd theta = model.nominal();
  for (int i = 0; i < theta.size(); ++i) {
    const ParameterInfo& p = model.parameters()[i];
    theta[i] =
        p.name == "beta" ? heading(*rng) : theta[i] + ParameterScale(p, model) * normal(*rng);
  }
  return theta;
}

StructuralReport AnalyzeStructure(const MeasurementModel& model, const Eigen::VectorXd& theta,
                                  const ObservabilityOptions& options) {
  StructuralReport report;
  report.model = model.name();
  report.params = model.num_parameters();
  report.theta = theta;
  Eigen::MatrixXd J;
  report.extended = static_cast<int>(model.Extended(theta, &J).size());
  report.analysis = AnalyzeRank(J, model, options);
  return report;
}

PoseDiversity AnalyzePoseDiversity(const std::vector<TablePose>& poses,
                                   const Eigen::Vector3d& v_ned,
                                   const ObservabilityOptions& options) {
  PoseDiversity d;
  d.poses = static_cast<int>(poses.size());
  if (poses.empty()) {
    d.findings.push_back("no poses");
    return d;
  }
  Eigen::MatrixXd A(poses.size(), 10);
  std::vector<Eigen::Vector3d> downs;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const auto r = static_cast<Eigen::Index>(i);
    A.block<1, 9>(r, 0) = LinearRegressor(poses[i], v_ned).transpose();
    A(r, 9) = 1.0;
    const Eigen::Vector3d down = poses[i].C_p_q().col(2);
    mean += down;
    const bool seen = std::any_of(downs.begin(), downs.end(), [&](const Eigen::Vector3d& other) {
      return (other - down).norm() < 1e-6;
    });
    if (!seen) downs.push_back(down);
  }
  d.distinct_down = static_cast<int>(downs.size());
  mean /= static_cast<double>(poses.size());
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const auto& p : poses) {
    const Eigen::Vector3d down = p.C_p_q().col(2) - mean;
    scatter += down * down.transpose();
  }
  scatter /= static_cast<double>(poses.size());
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(scatter);
  d.down_scatter = eig.eigenvalues().reverse();

  for (int c = 0; c < 10; ++c) {
    const double n = A.col(c).norm();
    if (n > 0) A.col(c) /= n;
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(A);
  const Eigen::VectorXd& s = svd.singularValues();
  for (int i = 0; i < s.size(); ++i) d.regressor_rank += s[i] > options.rank_tolerance * s[0];
  d.regressor_min_singular = s.size() == 10 && s[0] > 0 ? s[9] / s[0] : 0.0;

  auto axis_name = [](const Eigen::Vector3d& n) {
    return fmt::format("[{:+.3f} {:+.3f} {:+.3f}]", n.x(), n.y(), n.z());
  };
  if (d.distinct_down == 1) {
    const Eigen::Vector3d& down = downs[0];
    std::string which = "the z axis";
    if (std::abs(std::abs(down.z()) - 1.0) > 1e-6) which = "the direction " + axis_name(down);
    d.findings.push_back(fmt::format(
        "every pose has down along {} of the table frame: the poses differ only by a turn about "
        "the vertical (the outer, psi axis), so the sensor's response is seen along one direction "
        "only and its axis along down cannot be told from its bias",
        which));
  } else if (d.down_scatter[2] < 1e-9) {
    d.findings.push_back(fmt::format(
        "every down direction lies in one plane normal to {} of the table frame: the poses turn "
        "about that single axis",
        axis_name(eig.eigenvectors().col(0))));
  }
  if (d.regressor_rank < 10) {
    d.findings.push_back(fmt::format(
        "the linear form's regressor has rank {} of 10: these poses cannot determine G, beta and b",
        d.regressor_rank));
  }
  return d;
}

Jacobian3 RecordJacobian(const MeasurementModel& model, const Eigen::VectorXd& theta,
                         const WeightedPose& record) {
  Jacobian3 Ji;
  if (record.raw_residual) {
    // A move: its residual's Jacobian (core/estimation/move_residual.h).
    Eigen::Matrix<double, 3, Eigen::Dynamic, Eigen::RowMajor> Jr(3, theta.size());
    Eigen::Vector3d value;
    const double* parameters[] = {theta.data()};
    double* jacobians[] = {Jr.data()};
    record.raw_residual->Evaluate(parameters, value.data(), jacobians);
    Ji = Jr;
  } else {
    model.Predict(theta, record.pose, &Ji);
  }
  return Ji;
}

Eigen::MatrixXd WhitenedJacobian(const MeasurementModel& model, const Eigen::VectorXd& theta,
                                 const std::vector<WeightedPose>& poses) {
  Eigen::MatrixXd J(3 * poses.size(), model.num_parameters());
  for (std::size_t i = 0; i < poses.size(); ++i) {
    J.middleRows(3 * static_cast<Eigen::Index>(i), 3) =
        poses[i].sqrt_information * RecordJacobian(model, theta, poses[i]);
  }
  return J;
}

DataReport AnalyzeData(const MeasurementModel& model, const Eigen::VectorXd& theta,
                       const std::vector<WeightedPose>& poses,
                       const ObservabilityOptions& options) {
  DataReport report;
  const int N = model.num_parameters();
  report.model = model.name();
  report.params = N;
  report.poses = static_cast<int>(poses.size());
  report.expected_rank = N - model.gauge_dimension();
  report.theta = theta;
  const Eigen::MatrixXd J = WhitenedJacobian(model, theta, poses);
  report.fisher = J.transpose() * J;
  report.analysis = AnalyzeRank(J, model, options);
  std::vector<TablePose> table_poses;
  for (const auto& p : poses) table_poses.push_back(p.pose);
  report.diversity = AnalyzePoseDiversity(table_poses, model.excitation_ned(), options);

  // Cramer-Rao: the pseudo-inverse of the scaled Jacobian, in the gauge's tangent space for a
  // model with a gauge.
  Eigen::MatrixXd basis = Eigen::MatrixXd::Identity(N, N);  // raw units
  if (model.gauge_dimension() > 0) {
    basis = Mag22GaugeTangentBasis(model, theta);
    report.gauge = ToString(Mag22Gauge::kUnitDetKOrthogonalDeltaB);
  }
  Eigen::MatrixXd cov = Eigen::MatrixXd::Zero(N, N);
  if (J.rows() > 0) {
    const Eigen::MatrixXd JB = J * basis;
    Eigen::VectorXd col = JB.colwise().norm().transpose();
    for (int j = 0; j < col.size(); ++j) col[j] = col[j] > 0 ? 1.0 / col[j] : 1.0;
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(JB * col.asDiagonal(), Eigen::ComputeFullV);
    const Eigen::VectorXd& s = svd.singularValues();
    Eigen::VectorXd inv = Eigen::VectorXd::Zero(JB.cols());
    for (int i = 0; i < s.size(); ++i)
      if (s[0] > 0 && s[i] > options.rank_tolerance * s[0]) inv[i] = 1.0 / (s[i] * s[i]);
    const Eigen::MatrixXd T = basis * col.asDiagonal() * svd.matrixV();
    cov = T * inv.asDiagonal() * T.transpose();
  }
  report.sigma = cov.diagonal().cwiseMax(0.0).cwiseSqrt();

  // Null directions the gauge does not account for leave their parameters undetermined.
  for (const auto& d : report.analysis.null) {
    const Eigen::VectorXd v = OutsideGauge(model, theta, d.scaled);
    if (v.norm() < 1e-6) continue;
    for (int j = 0; j < N; ++j) {
      if (std::abs(v[j]) > kUndeterminedComponent) report.sigma[j] = INFINITY;
    }
  }
  return report;
}

Eigen::Matrix3d ExpectedSqrtInformation(double noise_density, double pose_offset_sigma,
                                        double dwell_s) {
  const double var =
      noise_density * noise_density / (2.0 * dwell_s) + pose_offset_sigma * pose_offset_sigma;
  return Eigen::Matrix3d::Identity() / std::sqrt(var);
}

}  // namespace turncal
