#pragma once
// What the calibration report (report/html.h) shows of one calibration, computed from
// its document with core's models, calibrator and observability analysis: residuals per pose
// before (nominal parameters) and after (the estimate), where the reference vector pointed in the
// sensor frame, each parameter's sigma as poses were added, and the data-level observability.
// Pure computation.

#include <Eigen/Core>
#include <cmath>
#include <string>
#include <vector>

#include "core/analysis/observability.h"
#include "core/analysis/rate_linearity.h"
#include "protocol/calibration_json.h"

namespace turncal::report {

// Residuals (measured mean - prediction) of the poses whose record carries the model's triad, in
// the triad's unit (m/s^2 for accelerometers, the device's unit for magnetometers).
struct PoseResiduals {
  std::vector<int> pose_index;              // index into the document's records
  std::vector<Eigen::Vector3d> before;      // at the model's nominal parameters
  std::vector<Eigen::Vector3d> after;       // at the estimate
  std::vector<Eigen::Vector3d> sigma_mean;  // 1 sigma of each pose mean as the calibrator weighs it
  Eigen::Vector3d rms_before = Eigen::Vector3d::Zero();  // per axis
  Eigen::Vector3d rms_after = Eigen::Vector3d::Zero();
  double rms_before_total = 0.0;  // over the three axes
  double rms_after_total = 0.0;
};

// Sigma of every parameter after the first k poses (the calibrator re-solved as the station did,
// warm-started pose by pose), k = first_k ... poses.
struct Convergence {
  std::vector<int> k;
  std::vector<Eigen::VectorXd> sigma;  // per k, in the model's order; NaN when not solved
  // The solve with every pose against the stored estimate: largest |difference| / sigma.
  double resolve_max_z = std::nan("");
  std::string note;  // when the re-solve is not possible or differs
};

// What each source of information determines (issue 21): every parameter's 1 sigma from the
// records of one source alone (static poses, rate segments), by the Fisher information at the
// estimate with each record weighed as the observability analysis weighs it; infinite where that
// source alone leaves the parameter undetermined.
struct SourceSigmas {
  std::vector<std::string> source;     // "static poses", "rate segments", "moves" (those present)
  std::vector<int> records;            // per source
  std::vector<Eigen::VectorXd> sigma;  // per source, in the model's order
  Eigen::VectorXd sigma_all;           // every record together, the same way
};

struct ModelAnalysis {
  bool has_records = false;       // false: only the coverage (from the table angles) is computed
  std::string no_records_reason;  // why, when !has_records
  PoseResiduals residuals;
  // Unit direction of the reference vector in the sensor's nominal case frame at each pose:
  // gravity g for accelerometers, the field B for magnetometers (M C_p^q R3(beta) v, with the
  // estimate's beta where the model has one).
  std::vector<Eigen::Vector3d> reference_dir_sensor;
  Convergence convergence;
  bool observability_done = false;
  DataReport observability;  // at the estimate over the document's records
  // For a gyroscope model whose records hold more than one kind (empty source list otherwise).
  SourceSigmas sources;
  // For a gyroscope model with rate segments: its scale against the rate
  // (core/analysis/rate_linearity.h; segments 0 otherwise).
  RateLinearity linearity;
};

// Everything above for one calibration document.
ModelAnalysis AnalyzeCalibration(const protocol::CalibrationDocument& doc);

}  // namespace turncal::report
