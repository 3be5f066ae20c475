#include "core/estimation/free_drift.h"

#include <Eigen/Cholesky>

namespace turncal {

Eigen::MatrixXd FreeDriftWhitener(const std::vector<FreeTerm>& terms, const Eigen::MatrixXd& J,
                                  const std::vector<FreeDriftTriad>& triads,
                                  const TimeWindow& reference, double origin_s,
                                  const CorrelatedChain* chain) {
  const int m = static_cast<int>(J.rows());
  // Each term's inputs: a triad's drift over a window, and the term's sensitivity to it.
  struct Input {
    const FreeDriftTriad* triad;
    TimeWindow window;
    Eigen::MatrixXd sensitivity;
    Eigen::Vector3d with_ref = Eigen::Vector3d::Zero();  // per axis, Cov(d(window), d(ref))
  };
  std::vector<std::vector<Input>> inputs(terms.size());
  std::vector<int> row(terms.size() + 1, 0);
  for (std::size_t i = 0; i < terms.size(); ++i) {
    const int k = terms[i].cost->num_residuals();
    row[i + 1] = row[i] + k;
    for (const FreeDriftTriad& t : triads) {
      if (t.bias_column >= 0) {
        Eigen::MatrixXd g = -J.block(row[i], t.bias_column, k, 3);
        if (!g.isZero(0.0))
          inputs[i].push_back({&t, terms[i].window, std::move(g), Eigen::Vector3d::Zero()});
      }
      for (const auto& extra : terms[i].extra_drift) {
        if (extra.triad == t.triad)
          inputs[i].push_back({&t, extra.window, extra.sensitivity, Eigen::Vector3d::Zero()});
      }
    }
  }
  std::vector<Eigen::Vector3d> ref_ref(triads.size());
  for (std::size_t t = 0; t < triads.size(); ++t) {
    for (int axis = 0; axis < 3; ++axis) {
      ref_ref[t][axis] = triads[t].drift.WindowCovariance(axis, reference, reference, origin_s);
    }
  }
  for (auto& list : inputs) {
    for (Input& in : list) {
      for (int axis = 0; axis < 3; ++axis) {
        in.with_ref[axis] = in.triad->drift.WindowCovariance(axis, in.window, reference, origin_s);
      }
    }
  }
  Eigen::MatrixXd S = Eigen::MatrixXd::Identity(m, m);
  for (std::size_t a = 0; a < terms.size(); ++a) {
    for (std::size_t b = a; b < terms.size(); ++b) {
      const int ka = row[a + 1] - row[a], kb = row[b + 1] - row[b];
      Eigen::MatrixXd block = Eigen::MatrixXd::Zero(ka, kb);
      for (const Input& x : inputs[a]) {
        for (const Input& y : inputs[b]) {
          if (x.triad != y.triad) continue;
          const auto t = static_cast<std::size_t>(x.triad - triads.data());
          Eigen::Vector3d c;
          for (int axis = 0; axis < 3; ++axis) {
            c[axis] = x.triad->drift.WindowCovariance(axis, x.window, y.window, origin_s) -
                      x.with_ref[axis] - y.with_ref[axis] + ref_ref[t][axis];
          }
          block += x.sensitivity * c.asDiagonal() * y.sensitivity.transpose();
        }
      }
      S.block(row[a], row[b], ka, kb) += block;
      if (b != a) S.block(row[b], row[a], kb, ka) += block.transpose();
    }
  }
  // The noise terms share: the same random vector behind each key.
  for (std::size_t a = 0; a < terms.size(); ++a) {
    for (std::size_t b = a; b < terms.size(); ++b) {
      for (const auto& x : terms[a].shared) {
        for (const auto& y : terms[b].shared) {
          if (x.key != y.key) continue;
          const Eigen::MatrixXd block = x.sensitivity * x.covariance * y.sensitivity.transpose();
          S.block(row[a], row[b], block.rows(), block.cols()) += block;
          if (b != a) S.block(row[b], row[a], block.cols(), block.rows()) += block.transpose();
        }
      }
    }
  }
  if (chain) AddChainCovariance(*chain, &S);
  Eigen::LLT<Eigen::MatrixXd> llt(S);
  return llt.matrixL().solve(Eigen::MatrixXd::Identity(m, m));
}

StackedFreeCost::StackedFreeCost(const std::vector<FreeTerm>& terms, Eigen::MatrixXd W, int n,
                                 int p)
    : terms_(terms), W_(std::move(W)), n_(n), p_(0) {
  for (const auto& t : terms_) {
    m_ += t.cost->num_residuals();
    if (t.upstream) p_ = p;
  }
  set_num_residuals(m_);
  mutable_parameter_block_sizes()->push_back(n_);
  if (p_ > 0) mutable_parameter_block_sizes()->push_back(p_);
}

bool StackedFreeCost::Evaluate(double const* const* parameters, double* residuals,
                               double** jacobians) const {
  using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  const bool want_t = jacobians && jacobians[0];
  const bool want_u = jacobians && p_ > 0 && jacobians[1];
  Eigen::VectorXd r(m_);
  RowMajor Jt = RowMajor::Zero(m_, n_), Ju = RowMajor::Zero(m_, std::max(p_, 1));
  int row = 0;
  for (const auto& t : terms_) {
    const int k = t.cost->num_residuals();
    RowMajor jt(k, n_), ju(k, std::max(p_, 1));
    std::vector<const double*> blocks = {parameters[0]};
    std::vector<double*> jac = {want_t ? jt.data() : nullptr};
    if (t.upstream) {
      blocks.push_back(parameters[1]);
      jac.push_back(want_u ? ju.data() : nullptr);
    }
    if (!t.cost->Evaluate(blocks.data(), r.data() + row, jacobians ? jac.data() : nullptr)) {
      return false;
    }
    if (want_t) Jt.middleRows(row, k) = jt;
    if (want_u && t.upstream) Ju.middleRows(row, k) = ju.leftCols(p_);
    row += k;
  }
  Eigen::Map<Eigen::VectorXd>(residuals, m_) = W_ * r;
  if (want_t) Eigen::Map<RowMajor>(jacobians[0], m_, n_) = W_ * Jt;
  if (want_u) Eigen::Map<RowMajor>(jacobians[1], m_, p_) = W_ * Ju.leftCols(p_);
  return true;
}

}  // namespace turncal
