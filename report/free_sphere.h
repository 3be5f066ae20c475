#pragma once
// The values on the sphere before and after a free calibration (issue 37), as the field tools draw
// them: the raw values of the model's triad (the still intervals' means and the magnetometer's
// samples in motion) offset and squashed into an ellipsoid by the hard and soft iron (or the
// accelerometer's bias and gains), and the same values corrected, on the sphere of the field's
// (gravity's) magnitude; in three projections (x-y, x-z, y-z), each with that sphere's circle.

#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "report/free_report.h"

namespace turncal::report {

struct SphereValues {
  std::vector<Eigen::Vector3d> before;  // raw, the triad's unit
  std::vector<Eigen::Vector3d> after;   // corrected, the same values
  double radius = 1.0;                  // the magnitude they are corrected to
  std::string unit;                     // of radius ("G", "relative", "m/s^2")
  std::string distortion;               // what squashes the raw values ("the hard and soft iron")
  std::int64_t of = 0;                  // values there were (every k-th drawn beyond max_values)
};

// The values of result `r` (a model of the magnetometer or the accelerometer with an estimate);
// nullopt for another model, one without an estimate, or no values.
std::optional<SphereValues> BeforeAfterValues(const FreeReportInput& in, const FreeModelResult& r,
                                              std::size_t max_values = 600);

// Three projections, before in grey (class "before") and after in red (class "after").
std::string BeforeAfterSvg(const SphereValues& values, const std::string& id);

}  // namespace turncal::report
