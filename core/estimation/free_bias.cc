#include "core/estimation/free_bias.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <cmath>
#include <vector>

namespace turncal {
namespace {

// The residual and Jacobian of every term (one scalar each) at theta; false when a term has more
// than one residual, an upstream block, or does not evaluate.
bool EvaluateScalarTerms(const std::vector<FreeTerm>& terms, const Eigen::VectorXd& theta,
                         Eigen::VectorXd* r, Eigen::MatrixXd* J) {
  const auto m = static_cast<Eigen::Index>(terms.size());
  const Eigen::Index n = theta.size();
  r->resize(m);
  J->resize(m, n);
  Eigen::VectorXd row(n);
  for (Eigen::Index i = 0; i < m; ++i) {
    const FreeTerm& t = terms[static_cast<std::size_t>(i)];
    if (t.upstream || t.cost->num_residuals() != 1) return false;
    const double* blocks[] = {theta.data()};
    double* jacobians[] = {row.data()};
    if (!t.cost->Evaluate(blocks, &(*r)[i], jacobians)) return false;
    J->row(i) = row.transpose();
  }
  return r->allFinite() && J->allFinite();
}

std::optional<TriadStats>& StatsOf(FreeInterval& interval, SensorKind triad) {
  return triad == SensorKind::kAccelerometer  ? interval.acc
         : triad == SensorKind::kMagnetometer ? interval.mag
                                              : interval.gyr;
}
const std::optional<TriadStats>& StatsOf(const FreeInterval& interval, SensorKind triad) {
  return StatsOf(const_cast<FreeInterval&>(interval), triad);
}

}  // namespace

std::optional<Eigen::VectorXd> NormFitBias(const FreeModel& model, const FreeData& data,
                                           const Eigen::VectorXd& theta,
                                           const NormBiasCorrelation* correlated) {
  const SensorKind triad = model.sensor();
  for (SensorKind k :
       {SensorKind::kAccelerometer, SensorKind::kGyroscope, SensorKind::kMagnetometer}) {
    if (k != triad && model.Needs(k)) return std::nullopt;
  }
  const std::vector<FreeTerm> terms = model.Terms(data, theta);
  const auto m = static_cast<Eigen::Index>(terms.size());
  const Eigen::Index n = theta.size();
  if (m <= n) return std::nullopt;
  std::vector<int> seen(data.intervals.size(), 0);
  for (const FreeTerm& t : terms) {
    if (t.kind != "norm" || t.interval < 0 ||
        t.interval >= static_cast<int>(data.intervals.size()) ||
        ++seen[static_cast<std::size_t>(t.interval)] > 1) {
      return std::nullopt;
    }
  }
  Eigen::VectorXd r0;
  Eigen::MatrixXd J0;
  if (!EvaluateScalarTerms(terms, theta, &r0, &J0)) return std::nullopt;

  // Each value's noise, whitened: m = m0 + R z (R R' its covariance, the drift's offset left out).
  std::vector<Eigen::Matrix3d> root(data.intervals.size(), Eigen::Matrix3d::Zero());
  for (std::size_t i = 0; i < data.intervals.size(); ++i) {
    if (const auto& s = StatsOf(data.intervals[i], triad)) {
      const Eigen::LLT<Eigen::Matrix3d> llt(MeanCovariance(*s, 0.0));
      if (llt.info() == Eigen::Success) root[i] = llt.matrixL();
    }
  }
  // Derivatives in z: the terms on values moved by +-1 sigma along each whitened axis (the
  // curvature's scale is |h| / sigma sigmas, so one sigma's step is exact to (sigma / |h|)^2).
  std::vector<Eigen::VectorXd> c(3), hzz(3);
  std::vector<Eigen::MatrixXd> dJ(3);
  for (int k = 0; k < 3; ++k) {
    Eigen::VectorXd r[2];
    Eigen::MatrixXd J[2];
    for (int side = 0; side < 2; ++side) {
      FreeData moved = data;
      const double step = side == 0 ? 1.0 : -1.0;
      for (std::size_t i = 0; i < moved.intervals.size(); ++i) {
        if (auto& s = StatsOf(moved.intervals[i], triad)) s->mean += step * root[i].col(k);
      }
      const std::vector<FreeTerm> t = model.Terms(moved, theta);
      if (static_cast<Eigen::Index>(t.size()) != m) return std::nullopt;
      if (!EvaluateScalarTerms(t, theta, &r[side], &J[side])) return std::nullopt;
    }
    c[k] = (r[0] - r[1]) / 2;
    hzz[k] = r[0] + r[1] - 2 * r0;
    dJ[k] = (J[0] - J[1]) / 2;
  }
  // The curvature in theta, per term: C_i's row p from the Jacobians at theta +- delta_p.
  const Eigen::VectorXd scales = model.Scales(data, theta);
  std::vector<Eigen::MatrixXd> C(static_cast<std::size_t>(m), Eigen::MatrixXd::Zero(n, n));
  for (Eigen::Index p = 0; p < n; ++p) {
    const double delta = 1e-5 * (std::isfinite(scales[p]) && scales[p] > 0 ? scales[p] : 1.0);
    Eigen::VectorXd at = theta, rp, rm;
    Eigen::MatrixXd Jp, Jm;
    at[p] += delta;
    if (!EvaluateScalarTerms(terms, at, &rp, &Jp)) return std::nullopt;
    at[p] -= 2 * delta;
    if (!EvaluateScalarTerms(terms, at, &rm, &Jm)) return std::nullopt;
    const Eigen::MatrixXd row = (Jp - Jm) / (2 * delta);
    for (Eigen::Index i = 0; i < m; ++i) C[static_cast<std::size_t>(i)].row(p) = row.row(i);
  }

  // A = J' Q J and its inverse in the model's scaled units (full rank only); Q = I when the
  // values are fitted as independent.
  const Eigen::MatrixXd* Q = correlated ? &correlated->weight : nullptr;
  const Eigen::MatrixXd* rho = correlated ? &correlated->noise : nullptr;
  if (Q && (Q->rows() != m || Q->cols() != m || rho->rows() != m || rho->cols() != m)) {
    return std::nullopt;
  }
  const Eigen::MatrixXd QJ = Q ? Eigen::MatrixXd(*Q * J0) : J0;
  Eigen::MatrixXd Ainv;
  if (!Q) {
    const Eigen::MatrixXd Js = J0 * scales.asDiagonal();
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd(Js, Eigen::ComputeThinV);
    const Eigen::VectorXd& s = svd.singularValues();
    if (!(s.size() == n && s[n - 1] > 1e-12 * s[0])) return std::nullopt;
    Ainv = scales.asDiagonal() * svd.matrixV() * s.cwiseInverse().cwiseAbs2().asDiagonal() *
           svd.matrixV().transpose() * scales.asDiagonal();
  } else {
    const Eigen::MatrixXd As = scales.asDiagonal() * (J0.transpose() * QJ) * scales.asDiagonal();
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(As);
    const Eigen::VectorXd& e = eig.eigenvalues();
    if (eig.info() != Eigen::Success || !(e[0] > 1e-24 * e[n - 1])) return std::nullopt;
    Ainv = scales.asDiagonal() * eig.eigenvectors() * e.cwiseInverse().asDiagonal() *
           eig.eigenvectors().transpose() * scales.asDiagonal();
  }
  // G = A^-1 J' Q: the first-order estimate is -G u, u_i = c_i' z_i. K = E[u u'] =
  // rho o (c c'), P = G K G' its covariance.
  const Eigen::MatrixXd G = Ainv * QJ.transpose();
  Eigen::MatrixXd cz(m, 3);
  for (int k = 0; k < 3; ++k) cz.col(k) = c[k];
  Eigen::MatrixXd GK, M[3];
  Eigen::MatrixXd both_c;  // (Q o rho) c: each value's noise against the weighted others'
  if (!Q) {
    const Eigen::VectorXd w = cz.rowwise().squaredNorm();
    GK = G * w.asDiagonal();
    for (int k = 0; k < 3; ++k) M[k] = G * c[k].asDiagonal();
    both_c = cz;
  } else {
    GK = G * rho->cwiseProduct(cz * cz.transpose());
    for (int k = 0; k < 3; ++k) M[k] = G * c[k].asDiagonal() * *rho;
    both_c = Q->cwiseProduct(*rho) * cz;
  }
  const Eigen::MatrixXd P = GK * G.transpose();
  const Eigen::MatrixXd GKQ = Q ? Eigen::MatrixXd(GK * *Q) : GK;

  Eigen::VectorXd g = Eigen::VectorXd::Zero(n);
  for (Eigen::Index i = 0; i < m; ++i) {
    const Eigen::VectorXd qa = QJ.row(i).transpose();
    const Eigen::MatrixXd& Ci = C[static_cast<std::size_t>(i)];
    double scalar = (Ci.cwiseProduct(P)).sum() / 2;  // tr(C_i P) / 2, both symmetric
    Eigen::VectorXd vector = Ci * (P * qa - GKQ.col(i));
    for (int k = 0; k < 3; ++k) {
      const Eigen::VectorXd b = dJ[k].row(i).transpose();
      scalar += hzz[k][i] / 2 - b.dot(M[k].col(i));
      vector += b * (both_c(i, k) - qa.dot(M[k].col(i)));
    }
    g += qa * scalar + vector;
  }
  const Eigen::VectorXd bias = -Ainv * g;
  if (!bias.allFinite()) return std::nullopt;
  return bias;
}

}  // namespace turncal
