#include "core/planning/drift_design.h"

#include <algorithm>
#include <cmath>

namespace turncal {

DriftDesign::DriftDesign(BiasDrift drift, int num_parameters)
    : drift_(std::move(drift)),
      n_params_(num_parameters),
      rows_(3, Eigen::MatrixXd(0, num_parameters)),
      chol_(3),
      whitened_(3, Eigen::MatrixXd(0, num_parameters)) {}

double DriftDesign::Origin(const TimeWindow& candidate) const {
  return windows_.empty() ? candidate.t0_s : windows_.front().t0_s;
}

void DriftDesign::Add(const Eigen::MatrixXd& jacobian, const Eigen::Vector3d& white_variance,
                      const TimeWindow& window) {
  windows_.push_back(window);
  white_.push_back(white_variance);
  for (int a = 0; a < 3; ++a) {
    Eigen::MatrixXd& r = rows_[static_cast<std::size_t>(a)];
    r.conservativeResize(r.rows() + 1, Eigen::NoChange);
    r.row(r.rows() - 1) = jacobian.row(a);
  }
  Refactor();
}

void DriftDesign::Refactor() {
  const int n = size();
  const double origin = windows_.front().t0_s;
  for (int a = 0; a < 3; ++a) {
    Eigen::MatrixXd C(n, n);
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j <= i; ++j) {
        C(i, j) = C(j, i) = drift_.WindowCovariance(a, windows_[static_cast<std::size_t>(i)],
                                                    windows_[static_cast<std::size_t>(j)], origin);
      }
      C(i, i) += white_[static_cast<std::size_t>(i)][a];
    }
    auto& llt = chol_[static_cast<std::size_t>(a)];
    llt.compute(C);
    whitened_[static_cast<std::size_t>(a)] =
        llt.matrixL().solve(rows_[static_cast<std::size_t>(a)]);
  }
}

Eigen::MatrixXd DriftDesign::InnovationRows(const Eigen::MatrixXd& jacobian,
                                            const Eigen::Vector3d& white_variance,
                                            const TimeWindow& window) const {
  const int n = size();
  const double origin = Origin(window);
  Eigen::MatrixXd out(3, n_params_);
  Eigen::VectorXd k(n);
  for (int a = 0; a < 3; ++a) {
    double s = drift_.WindowCovariance(a, window, window, origin) + white_variance[a];
    Eigen::RowVectorXd row = jacobian.row(a);
    if (n > 0) {
      for (int i = 0; i < n; ++i) {
        k[i] = drift_.WindowCovariance(a, windows_[static_cast<std::size_t>(i)], window, origin);
      }
      const Eigen::VectorXd v = chol_[static_cast<std::size_t>(a)].matrixL().solve(k);
      s -= v.squaredNorm();
      row -= v.transpose() * whitened_[static_cast<std::size_t>(a)];
    }
    // The innovation's variance is at least the pose's own white noise minus rounding.
    s = std::max(s, 1e-12 * white_variance[a]);
    out.row(a) = row / std::sqrt(s);
  }
  return out;
}

Eigen::MatrixXd DriftDesign::Information() const {
  Eigen::MatrixXd F = Eigen::MatrixXd::Zero(n_params_, n_params_);
  for (const auto& w : whitened_) F += w.transpose() * w;
  return F;
}

Eigen::MatrixXd DriftDesign::InformationAtLatest() const {
  Eigen::MatrixXd F = Eigen::MatrixXd::Zero(n_params_, n_params_);
  if (windows_.empty()) return F;
  const int ref = TimeOrder(windows_).back();
  for (int a = 0; a < 3; ++a) {
    Eigen::MatrixXd C = DriftIncrementCovariance(drift_, a, windows_, ref);
    for (int i = 0; i < size(); ++i) C(i, i) += white_[static_cast<std::size_t>(i)][a];
    const Eigen::LLT<Eigen::MatrixXd> llt(C);
    const Eigen::MatrixXd w = llt.matrixL().solve(rows_[static_cast<std::size_t>(a)]);
    F += w.transpose() * w;
  }
  return F;
}

}  // namespace turncal
