#pragma once
// The Fisher information of a sequence of timed poses when the bias drifts
// (core/estimation/bias_drift.h), for the pose planner: what a pose adds depends on when it is
// taken, because its error shares the drift with the poses near it in time.
//
// Two equivalent views of one model (docs/ACCURACY.md "Drift"). With the bias parameters free
// (a flat prior), the information about every other parameter is the same whether the pose
// errors are the absolute wander ubar_i (the bias parameter then holds the wander's mean level)
// or the increments ubar_i - ubar_ref (the calibrator's: the bias over the latest window). The
// first is convenient for appending a pose: its information given the earlier poses is that of
// its innovation. The second gives the bias sigma the gate judges. Both are kept per axis: the
// drift is independent per axis and each pose's white covariance is taken as its diagonal.

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <vector>

#include "core/estimation/bias_drift.h"

namespace turncal {

class DriftDesign {
 public:
  DriftDesign(BiasDrift drift, int num_parameters);

  // Appends a pose taken after all earlier ones: its Jacobian (3 x N, in whatever column
  // scaling the caller uses throughout), its white variance per axis (> 0) and its window.
  void Add(const Eigen::MatrixXd& jacobian, const Eigen::Vector3d& white_variance,
           const TimeWindow& window);
  int size() const { return static_cast<int>(windows_.size()); }
  const std::vector<TimeWindow>& windows() const { return windows_; }

  // The whitened rows (3 x N) a pose taken after all others would add: its innovation given
  // them, so that Information() + rows^T rows is the information with it.
  Eigen::MatrixXd InnovationRows(const Eigen::MatrixXd& jacobian,
                                 const Eigen::Vector3d& white_variance,
                                 const TimeWindow& window) const;
  // J^T C^-1 J over the poses (absolute wander).
  Eigen::MatrixXd Information() const;
  // The same with the bias referred to the latest window (the calibrator's parametrisation).
  Eigen::MatrixXd InformationAtLatest() const;

 private:
  double Origin(const TimeWindow& candidate) const;
  void Refactor();

  BiasDrift drift_;
  int n_params_;
  std::vector<TimeWindow> windows_;
  std::vector<Eigen::Vector3d> white_;
  std::vector<Eigen::MatrixXd> rows_;  // per axis: poses x N
  // Per axis: the Cholesky factor of the absolute covariance and L^-1 rows.
  std::vector<Eigen::LLT<Eigen::MatrixXd>> chol_;
  std::vector<Eigen::MatrixXd> whitened_;
};

}  // namespace turncal
