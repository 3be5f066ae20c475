#pragma once
// What the free models (accel9, gyro9, magellipsoid, magsphere, accmag) share: the triangular
// and symmetric matrices of their parameters, the algebraic sphere and ellipsoid fits they start
// from, the norm residual |correct(raw)| = magnitude and its whitening.

#include <ceres/autodiff_cost_function.h>
#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/frames/rotations.h"
#include "core/modeling/free_model.h"
#include "core/modeling/parameter_matrices.h"

namespace turncal::free {

// The parameter blocks' matrices (core/modeling/parameter_matrices.h).
using params::FullTK;
using params::Symmetric;
using params::UpperTK;
using params::Vector;

// The 9 parameters of UpperTK from an upper-triangular C with a positive diagonal.
inline void UpperTKFromMatrix(const Eigen::Matrix3d& C, double* p) {
  for (int i = 0; i < 3; ++i) p[i] = C(i, i);
  p[3] = -C(0, 1) / C(1, 1);
  p[4] = C(0, 2) / C(2, 2);
  p[5] = -C(1, 2) / C(2, 2);
}

// An algebraic fit of the quadric x^T A x + 2 x^T u + c = 0 through the points (the smallest
// singular vector of [x^2 y^2 z^2 2xy 2xz 2yz 2x 2y 2z 1], the points centred and scaled first),
// written as (x - center)^T E (x - center) = 1; nullopt when it is not an ellipsoid (too few
// points, or points that leave it a hyperboloid or a cylinder).
struct Ellipsoid {
  Eigen::Vector3d center;
  Eigen::Matrix3d E;
};
inline std::optional<Ellipsoid> FitEllipsoid(const std::vector<Eigen::Vector3d>& points) {
  const int n = static_cast<int>(points.size());
  if (n < 9) return std::nullopt;
  Eigen::Vector3d mu = Eigen::Vector3d::Zero();
  for (const auto& p : points) mu += p;
  mu /= n;
  double s = 0;
  for (const auto& p : points) s += (p - mu).squaredNorm();
  s = std::sqrt(s / n);
  if (!(s > 0)) return std::nullopt;
  Eigen::MatrixXd D(n, 10);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d x = (points[i] - mu) / s;
    D.row(i) << x.x() * x.x(), x.y() * x.y(), x.z() * x.z(), 2 * x.x() * x.y(), 2 * x.x() * x.z(),
        2 * x.y() * x.z(), 2 * x.x(), 2 * x.y(), 2 * x.z(), 1.0;
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(D, Eigen::ComputeFullV);
  const Eigen::VectorXd v = svd.matrixV().col(9);
  Eigen::Matrix3d A;
  A << v[0], v[3], v[4], v[3], v[1], v[5], v[4], v[5], v[2];
  const Eigen::Vector3d u(v[6], v[7], v[8]);
  if (std::abs(A.determinant()) < 1e-12) return std::nullopt;
  const Eigen::Vector3d c = -A.inverse() * u;
  const double k = c.dot(A * c) - v[9];
  Eigen::Matrix3d E = A / k;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(E);
  if (!(eig.eigenvalues().minCoeff() > 0) || !E.allFinite()) return std::nullopt;
  return Ellipsoid{mu + s * c, E / (s * s)};
}

// A sphere |x - center| = radius by linear least squares (|x|^2 = 2 x.c + r^2 - |c|^2); nullopt
// with fewer than 4 points or points on a plane.
struct Sphere {
  Eigen::Vector3d center;
  double radius = 0.0;
};
inline std::optional<Sphere> FitSphere(const std::vector<Eigen::Vector3d>& points) {
  const int n = static_cast<int>(points.size());
  if (n < 4) return std::nullopt;
  Eigen::Vector3d mu = Eigen::Vector3d::Zero();
  for (const auto& p : points) mu += p;
  mu /= n;
  Eigen::MatrixXd A(n, 4);
  Eigen::VectorXd y(n);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d x = points[i] - mu;
    A.row(i) << 2 * x.x(), 2 * x.y(), 2 * x.z(), 1.0;
    y[i] = x.squaredNorm();
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const Eigen::VectorXd& sv = svd.singularValues();
  if (!(sv[3] > 1e-9 * sv[0])) return std::nullopt;
  const Eigen::VectorXd x = svd.solve(y);
  const double r2 = x[3] + x.head<3>().squaredNorm();
  if (!(r2 > 0)) return std::nullopt;
  return Sphere{mu + x.head<3>(), std::sqrt(r2)};
}

// The symmetric square root of a symmetric positive definite matrix.
inline Eigen::Matrix3d SqrtSymmetric(const Eigen::Matrix3d& E) {
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(E);
  return eig.eigenvectors() * eig.eigenvalues().cwiseMax(0).cwiseSqrt().asDiagonal() *
         eig.eigenvectors().transpose();
}

// The residual (|Correct(theta, raw)| - magnitude) / sigma, sigma the first-order standard
// deviation of |x| from the raw mean's covariance at the whitening point. `Correction` provides
// template <typename T> static Vec3<T> Apply(const T* theta, const Vec3<T>& raw).
template <class Correction, int N>
struct NormFunctor {
  Eigen::Vector3d raw;
  double magnitude = 1.0;
  double inv_sigma = 1.0;
  template <typename T>
  bool operator()(const T* theta, T* r) const {
    const Vec3<T> x = Correction::Apply(theta, Vec3<T>(raw.cast<T>()));
    r[0] = (x.norm() - T(magnitude)) * T(inv_sigma);
    return true;
  }
};

// sigma of |x| for x = L (raw - b) (L the correction's linear part at the whitening point).
inline double NormSigma(const Eigen::Matrix3d& L, const Eigen::Vector3d& x,
                        const Eigen::Matrix3d& raw_covariance) {
  const Eigen::Vector3d n = x.normalized();
  const Eigen::RowVector3d j = n.transpose() * L;
  return std::sqrt(std::max(1e-300, double(j * raw_covariance * j.transpose())));
}

template <class Correction, int N>
std::unique_ptr<ceres::CostFunction> MakeNormCost(const Eigen::Vector3d& raw, double magnitude,
                                                  double sigma) {
  auto* f = new NormFunctor<Correction, N>{raw, magnitude, 1.0 / sigma};
  return std::make_unique<ceres::AutoDiffCostFunction<NormFunctor<Correction, N>, 1, N>>(f);
}

// An interval's window on the sensor's clock.
inline TimeWindow Window(const FreeInterval& interval) {
  return TimeWindow{interval.sensor_start_s(), interval.sensor_end_s()};
}

// The means of the intervals that carry `triad`, and their covariances.
inline void Means(const FreeData& data, SensorKind triad, double offset_sigma,
                  std::vector<Eigen::Vector3d>* means, std::vector<Eigen::Matrix3d>* covariances,
                  std::vector<int>* index) {
  for (int i = 0; i < static_cast<int>(data.intervals.size()); ++i) {
    const TriadStats* s = triad == SensorKind::kAccelerometer
                              ? (data.intervals[i].acc ? &*data.intervals[i].acc : nullptr)
                          : triad == SensorKind::kMagnetometer
                              ? (data.intervals[i].mag ? &*data.intervals[i].mag : nullptr)
                              : (data.intervals[i].gyr ? &*data.intervals[i].gyr : nullptr);
    if (!s || s->count <= 0) continue;
    means->push_back(s->mean);
    if (covariances) covariances->push_back(MeanCovariance(*s, offset_sigma));
    if (index) index->push_back(i);
  }
}

// The field's magnitude the magnetometer models correct to: the reference's, or 1 (relative)
// when it is not known.
inline double FieldMagnitude(const FreeContext& context) {
  return context.field_magnitude > 0 ? context.field_magnitude : 1.0;
}

// A free model of one triad whose corrected mean has a known magnitude in every still interval
// (accel9: gravity; magellipsoid, magsphere: the field): one "norm" term per interval, its misfits
// the corrected means' norms less that magnitude, its direction the corrected mean. A model names
// itself, its triad, where its bias starts in theta and the magnitude; it fills params_.
class NormFreeModel : public FreeModel {
 public:
  const std::string& name() const override { return name_; }
  SensorKind sensor() const override { return sensor_; }
  bool Needs(SensorKind t) const override { return t == sensor_; }
  const std::vector<ParameterInfo>& parameters() const override { return params_; }
  std::vector<std::pair<SensorKind, int>> BiasColumns() const override {
    return {{sensor_, bias_column_}};
  }
  std::vector<Misfit> Misfits(const FreeData& data, const Eigen::VectorXd& theta) const override {
    std::vector<Misfit> out;
    for (int k = 0; k < static_cast<int>(data.intervals.size()); ++k) {
      if (const TriadStats* t = Triad(data.intervals[static_cast<std::size_t>(k)])) {
        out.push_back({"norm", k,
                       Correct(theta, t->mean).norm() -
                           Magnitude(data.intervals[static_cast<std::size_t>(k)])});
      }
    }
    return out;
  }
  Eigen::Vector3d Direction(const FreeData&, const Eigen::VectorXd& theta,
                            const FreeInterval& interval) const override {
    const TriadStats* t = Triad(interval);
    return t ? Correct(theta, t->mean) : Eigen::Vector3d::Zero();
  }

 protected:
  NormFreeModel(std::string name, SensorKind sensor, int bias_column, double magnitude)
      : name_(std::move(name)), sensor_(sensor), bias_column_(bias_column), magnitude_(magnitude) {}

  // |Correct(mean)| in every still interval: gravity, or the field's magnitude.
  double magnitude() const { return magnitude_; }
  // ... over `interval`: a magnetometer's sample in motion's attenuated by its bandwidth.
  double Magnitude(const FreeInterval& interval) const {
    return sensor_ == SensorKind::kMagnetometer ? magnitude_ * interval.mag_attenuation
                                                : magnitude_;
  }
  // The model's triad over `interval` (null when the interval has none).
  const TriadStats* Triad(const FreeInterval& interval) const {
    const std::optional<TriadStats>& t = sensor_ == SensorKind::kAccelerometer ? interval.acc
                                         : sensor_ == SensorKind::kGyroscope   ? interval.gyr
                                                                               : interval.mag;
    return t ? &*t : nullptr;
  }
  // The means of the intervals that carry the triad (for a start).
  std::vector<Eigen::Vector3d> RawMeans(const FreeData& data) const {
    std::vector<Eigen::Vector3d> means;
    Means(data, sensor_, 0, &means, nullptr, nullptr);
    return means;
  }
  // Whether the triad turned: the means must spread about their centroid (the largest principal
  // axis) by at least kMinTurnSpread times their own noise (the median per-axis sigma of a mean),
  // or no sphere or ellipsoid is determined by them -- a tiny one about a cloud of noise fits as
  // well (a frozen sensor, a device that was never turned, a capture of nothing but noise). False
  // with the reason in *error.
  static constexpr double kMinTurnSpread = 20.0;
  bool Turned(const FreeData& data, std::string* error) const {
    std::vector<Eigen::Vector3d> means;
    std::vector<Eigen::Matrix3d> covariances;
    std::vector<int> index;
    Means(data, sensor_, 0.0, &means, &covariances, &index);
    if (means.size() < 2) return true;  // the start and the rank test say what is missing
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (const auto& m : means) centroid += m;
    centroid /= static_cast<double>(means.size());
    Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
    for (const auto& m : means) scatter += (m - centroid) * (m - centroid).transpose();
    scatter /= static_cast<double>(means.size());
    const double spread = std::sqrt(std::max(
        0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(scatter).eigenvalues().maxCoeff()));
    std::vector<double> sigmas;
    for (const auto& c : covariances) sigmas.push_back(std::sqrt(std::max(0.0, c.trace() / 3)));
    std::nth_element(sigmas.begin(),
                     sigmas.begin() + static_cast<std::ptrdiff_t>(sigmas.size() / 2), sigmas.end());
    const double noise = sigmas[sigmas.size() / 2];
    if (spread >= kMinTurnSpread * noise && spread > 0) return true;
    if (error) {
      const char* triad = sensor_ == SensorKind::kMagnetometer ? "magnetometer" : "accelerometer";
      *error =
          spread == 0
              ? fmt::format("the {}'s {} values are all the same: a frozen sensor", triad,
                            means.size())
              : fmt::format(
                    "the {} did not turn: its {} values spread {:.3g} about their mean, {:.1f} "
                    "times their noise ({:.3g}; at least {:.0f} needed) -- a device that was "
                    "not turned, or a capture of nothing but noise",
                    triad, means.size(), spread, noise > 0 ? spread / noise : 0.0, noise,
                    kMinTurnSpread);
    }
    return false;
  }
  // One "norm" term per interval that carries the triad, its cost `make(mean, covariance,
  // magnitude)` (the mean's covariance with the triad's offset sigma; the magnitude expected over
  // the interval, Magnitude).
  template <class MakeCost>
  std::vector<FreeTerm> NormTerms(const FreeData& data, MakeCost make) const {
    const double offset_sigma = sensor_ == SensorKind::kAccelerometer
                                    ? data.context.acc_offset_sigma
                                : sensor_ == SensorKind::kGyroscope ? data.context.gyr_offset_sigma
                                                                    : data.context.mag_offset_sigma;
    std::vector<Eigen::Vector3d> means;
    std::vector<Eigen::Matrix3d> covariances;
    std::vector<int> index;
    Means(data, sensor_, offset_sigma, &means, &covariances, &index);
    std::vector<FreeTerm> terms;
    for (std::size_t i = 0; i < means.size(); ++i) {
      FreeTerm t;
      t.cost = make(means[i], covariances[i], Magnitude(data.intervals[index[i]]));
      t.interval = index[i];
      t.kind = "norm";
      t.window = Window(data.intervals[index[i]]);
      terms.push_back(std::move(t));
    }
    return terms;
  }

  std::vector<ParameterInfo> params_;

 private:
  std::string name_;
  SensorKind sensor_;
  int bias_column_;
  double magnitude_;
};

}  // namespace turncal::free
