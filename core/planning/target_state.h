#pragma once
// The greedy pose planner's view of one target (core/planning/pose_planner.cc): the rows a
// record would add to the target's information and the information as records are taken in
// (with a drift model, through the drift design in time order), in scaled units.

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <optional>
#include <string>
#include <vector>

#include "core/modeling/mag22_gauge.h"
#include "core/planning/drift_design.h"
#include "core/planning/pose_planner.h"

namespace turncal::planning {

// The rows a record would add, in scaled units: whitened without drift; with drift unwhitened,
// with its white variance per axis (the drift design whitens it given the earlier records). No
// rows: the record tells the model nothing (a rate segment for an accelerometer).
struct PlannedRows {
  Eigen::MatrixXd J;
  Eigen::Vector3d white = Eigen::Vector3d::Ones();
};

// One target's state during the greedy search, in scaled units.
struct TargetState {
  const PlanningTarget* target = nullptr;
  bool gyro = false;
  Eigen::VectorXd scales;
  Eigen::MatrixXd information;    // D F D + prior (absolute wander with drift)
  std::vector<PlannedRows> cand;  // per candidate
  int records = 0;                // poses, rate segments and moves (3 rows each)
  int poses = 0, rate_segments = 0, moves = 0;
  bool gauge_blocks = false;
  // With drift: the records in time order, captured then planned, and the clock.
  std::optional<DriftDesign> design;
  double t_now_s = 0.0;  // the end of the latest window on the target's clock
  Eigen::MatrixXd prior;

  void Refresh() {
    if (design) information = design->Information() + prior;
  }

  // A record's rows when its window is `w`: its innovation given every earlier one with drift.
  Eigen::MatrixXd Rows(const PlannedRows& r, const TimeWindow& w) const {
    if (!design || r.J.rows() == 0) return r.J;
    return design->InnovationRows(r.J, r.white, w);
  }

  // Takes the record in; false when it has no rows.
  bool Append(const PlannedRows& r, const TimeWindow& w) {
    if (r.J.rows() == 0) return false;
    ++records;
    if (!design) {
      information += r.J.transpose() * r.J;
      return true;
    }
    design->Add(r.J, r.white, w);
    Refresh();
    return true;
  }

  Eigen::VectorXd Sigma() const {
    const MeasurementModel& model = *target->model;
    const int N = model.num_parameters();
    // The gate judges the bias over the latest window (the calibrator's parametrisation).
    const Eigen::MatrixXd F = design && design->size() > 0
                                  ? Eigen::MatrixXd(design->InformationAtLatest() + prior)
                                  : information;
    if (model.gauge_dimension() == 0) {
      const Eigen::MatrixXd cov = F.ldlt().solve(Eigen::MatrixXd::Identity(N, N));
      return scales.cwiseProduct(cov.diagonal().cwiseMax(0.0).cwiseSqrt());
    }
    const Eigen::MatrixXd F_raw =
        scales.cwiseInverse().asDiagonal() * F * scales.cwiseInverse().asDiagonal();
    const Eigen::MatrixXd B = Mag22GaugeTangentBasis(model, target->theta);
    const Eigen::MatrixXd inner = B.transpose() * F_raw * B;
    const Eigen::MatrixXd cov =
        B * inner.ldlt().solve(Eigen::MatrixXd::Identity(B.cols(), B.cols())) * B.transpose();
    return cov.diagonal().cwiseMax(0.0).cwiseSqrt();
  }

  bool Passes(const Eigen::VectorXd& sigma, std::vector<std::string>* shortfalls) const {
    const MeasurementModel& model = *target->model;
    *shortfalls = PrecisionShortfalls(model, sigma, target->gate);
    const int rank = model.num_parameters() - model.gauge_dimension();
    if (3 * records - rank < target->gate.min_dof) {
      shortfalls->push_back(fmt::format("{} records leave {} degrees of freedom; the gate needs {}",
                                        records, 3 * records - rank, target->gate.min_dof));
    }
    return shortfalls->empty() && !gauge_blocks;
  }
};

// The diagonal of the covariance whose inverse square root is `sqrt_information`.
Eigen::Vector3d WhiteVariance(const Eigen::Matrix3d& sqrt_information);

// log det (I + J F^-1 J^T): what the rows J add to log det F, F factored as `information`.
double LogDetGain(const Eigen::MatrixXd& J, const Eigen::LDLT<Eigen::MatrixXd>& information);

// What a candidate gives a target: a static pose's prediction, weighed like a dwell; a rate
// segment's for a gyroscope, weighed over its whole revolutions with the table's rate accuracy
// (as Calibrator::add_pose weighs it); nothing otherwise.
PlannedRows CandidateRows(const TargetState& s, const TablePose& pose, double dwell_s);

// The move from static `from` to static `to` as the calibrator would weigh it (Calibrator::
// add_move: Qbar and the white covariance at the nominal parameters); no rows when the target
// credits no moves or the move cannot be formed.
PlannedRows MoveRows(const TargetState& s, const PlannerOptions& options, const TablePose& from,
                     const TablePose& to);

// a's rows above b's (either may have none).
Eigen::MatrixXd Stack(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b);

}  // namespace turncal::planning
