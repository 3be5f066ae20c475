#include "core/estimation/drift_identify.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <cmath>

namespace turncal {

BiasDrift ScaledDrift(const BiasDrift& drift, double scale) {
  BiasDrift d = drift;
  d.gm_sigma *= scale;
  d.rw_density *= scale;
  d.warmup_sigma *= scale;
  return d;
}

namespace {

// The restricted log-likelihood of the residuals at drift scale s (constants dropped), or NaN
// when it is not defined. Per axis C(s) = W + s^2 D with W diagonal: with M = W^-1/2 D W^-1/2 =
// Q diag(lambda) Q^T (once), C(s)^-1 = W^-1/2 Q diag(1 / (1 + s^2 lambda)) Q^T W^-1/2 and
// log det C(s) = log det W + sum log(1 + s^2 lambda), so each s costs O(n N^2), not a Cholesky.
class Reml {
 public:
  Reml(const Eigen::MatrixXd& J, const Eigen::VectorXd& r,
       const std::vector<Eigen::Vector3d>& white, const std::vector<TimeWindow>& windows,
       const BiasDrift& prior)
      : N_(static_cast<int>(J.cols())) {
    const int n = static_cast<int>(windows.size());
    const int ref = TimeOrder(windows).back();
    for (int a = 0; a < 3; ++a) {
      Eigen::VectorXd w_inv_sqrt(n);
      Eigen::MatrixXd Ja(n, N_);
      Eigen::VectorXd ra(n);
      for (int i = 0; i < n; ++i) {
        w_inv_sqrt[i] = 1.0 / std::sqrt(white[static_cast<std::size_t>(i)][a]);
        Ja.row(i) = J.row(3 * i + a) * w_inv_sqrt[i];
        ra[i] = r[3 * i + a] * w_inv_sqrt[i];
      }
      const Eigen::MatrixXd M = w_inv_sqrt.asDiagonal() *
                                DriftIncrementCovariance(prior, a, windows, ref) *
                                w_inv_sqrt.asDiagonal();
      const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(M);
      lambda_[a] = eig.eigenvalues().cwiseMax(0.0);
      J_[a] = eig.eigenvectors().transpose() * Ja;
      r_[a] = eig.eigenvectors().transpose() * ra;
    }
  }

  double operator()(double s) const {
    double logdet = 0, quad = 0;
    Eigen::MatrixXd F = Eigen::MatrixXd::Zero(N_, N_);
    Eigen::VectorXd g = Eigen::VectorXd::Zero(N_);
    for (int a = 0; a < 3; ++a) {
      const Eigen::ArrayXd d = 1.0 + s * s * lambda_[a].array();
      logdet += d.log().sum();
      const Eigen::VectorXd inv = d.inverse().matrix();
      F.noalias() += J_[a].transpose() * inv.asDiagonal() * J_[a];
      g.noalias() += J_[a].transpose() * inv.cwiseProduct(r_[a]);
      quad += r_[a].cwiseAbs2().dot(inv);
    }
    const Eigen::LDLT<Eigen::MatrixXd> ldlt(F);
    const Eigen::VectorXd diag = ldlt.vectorD();
    if ((diag.array() <= 0).any()) return NAN;
    // r^T P r with P = C^-1 - C^-1 J F^-1 J^T C^-1.
    quad -= g.dot(ldlt.solve(g));
    return -0.5 * (logdet + diag.array().log().sum() + quad);
  }

 private:
  int N_;
  Eigen::VectorXd lambda_[3], r_[3];
  Eigen::MatrixXd J_[3];
};

// The maximum of f on [lo, hi] by golden-section search, to 0.005.
template <typename F>
double GoldenMax(F f, double lo, double hi) {
  const double phi = 0.5 * (std::sqrt(5.0) - 1);
  double x1 = hi - phi * (hi - lo), x2 = lo + phi * (hi - lo);
  double f1 = f(x1), f2 = f(x2);
  while (hi - lo > 0.005) {
    if (f1 < f2) {
      lo = x1;
      x1 = x2;
      f1 = f2;
      x2 = lo + phi * (hi - lo);
      f2 = f(x2);
    } else {
      hi = x2;
      x2 = x1;
      f2 = f1;
      x1 = hi - phi * (hi - lo);
      f1 = f(x1);
    }
  }
  return 0.5 * (lo + hi);
}

}  // namespace

DriftScale IdentifyDriftScale(const Eigen::MatrixXd& jacobian, const Eigen::VectorXd& residuals,
                              const std::vector<Eigen::Vector3d>& white,
                              const std::vector<TimeWindow>& windows, const BiasDrift& prior,
                              const DriftScaleOptions& options) {
  DriftScale out;
  out.prior_log_sigma = options.prior_log_sigma;
  const int n = static_cast<int>(windows.size());
  if (!prior.enabled() || n < 2 || jacobian.rows() != 3 * n || residuals.size() != 3 * n ||
      static_cast<int>(white.size()) != n || jacobian.cols() >= 3 * n) {
    return out;
  }
  const Reml reml(jacobian, residuals, white, windows, prior);
  const double p2 = options.prior_log_sigma * options.prior_log_sigma;
  // The log-likelihood of u = ln s, and the log-posterior.
  auto like = [&](double u) {
    const double l = reml(std::exp(u));
    return std::isfinite(l) ? l : -INFINITY;
  };
  auto post = [&](double u) { return like(u) - 0.5 * u * u / p2; };
  const double lo = std::log(options.min_scale), hi = std::log(options.max_scale);
  const double u_post = GoldenMax(post, lo, hi), u_data = GoldenMax(like, lo, hi);
  // Curvatures by central differences.
  const double h = 0.05;
  auto curvature = [&](auto f, double u) { return -(f(u + h) - 2 * f(u) + f(u - h)) / (h * h); };
  const double c_post = curvature(post, u_post), c_data = curvature(like, u_data);
  if (!std::isfinite(c_post) || !std::isfinite(c_data)) return out;
  out.identified = true;
  out.scale = std::exp(u_post);
  out.log_sigma = c_post > 0 ? 1.0 / std::sqrt(c_post) : INFINITY;
  out.data_scale = std::exp(u_data);
  out.data_log_sigma = c_data > 0 ? 1.0 / std::sqrt(c_data) : INFINITY;
  // The likelihood-ratio test of the configured scale 1 (at a bound of the search too, where a
  // drift far below the white noise leaves the likelihood flat).
  const double l_max = like(u_data), l_one = like(0.0);
  const double z2 = options.reject_prior_z * options.reject_prior_z;
  out.rejects_prior = std::isfinite(l_max) && std::isfinite(l_one) && 2 * (l_max - l_one) > z2;
  out.use_scale = 1.0;
  if (out.rejects_prior && u_data > 0) {
    out.use_scale = out.data_scale;
  } else if (out.rejects_prior) {
    // Smaller than configured: the largest scale the poses allow at 95 % (2 (l_max - l) = 3.84),
    // between their estimate and 1. A drift under the white noise is poorly determined, and its
    // estimate may sit at the search's bound; erring small would make the sigma optimistic.
    double a = u_data, b = 0.0;
    for (int i = 0; i < 40; ++i) {
      const double m = 0.5 * (a + b);
      (2 * (l_max - like(m)) < 3.84 ? a : b) = m;
    }
    out.use_scale = std::exp(b);
  }
  return out;
}

}  // namespace turncal
