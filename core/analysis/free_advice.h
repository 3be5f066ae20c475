#pragma once
// Which orientation to add to a tumble (issue 22, observability for a tumble): each candidate is
// a few hypothetical static intervals the current estimate predicts, weighed by the information
// they would add to the weakest direction of the free model's Fisher information (columns scaled
// as the rank test scales them). The candidates are what a hand can do:
//  - accelerometer: point one of the 26 axis, edge and corner directions of the case up;
//  - magnetometer: point one of the 14 axis and corner directions up and turn the device about the
//    vertical through a full turn (8 stops), which sweeps the field around a cone;
//  - gyroscope: from the last interval, turn 90 degrees about one of the six case axes that is
//    not near vertical (a turn about the vertical leaves gravity's direction as it was, so the
//    gyro residual cannot see it).
// Pure computation.

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include "core/estimation/free_calibrator.h"

namespace turncal {

struct OrientationAdvice {
  std::string text;  // "point +x up", "point +y up and turn it about the vertical (8 stops)"
  Eigen::Vector3d axis = Eigen::Vector3d::Zero();  // the case direction named
  // The smallest eigenvalue of the scaled information before and with the candidate, and the
  // weakest direction's sigma relative to now (sqrt of their ratio).
  double information_before = 0.0, information_after = 0.0;
  double sigma_ratio = 1.0;
};

// The best candidate for `model` at `estimate`, or nullopt when the model has no candidates (no
// estimate, or a gyroscope without an interval to turn from).
std::optional<OrientationAdvice> NextOrientation(const FreeModel& model, const FreeData& data,
                                                 const FreeEstimate& estimate);

// The next orientation for each of `results` (CalibrateFreeModels's, in its order), each model
// weighed with its upstream's estimate where it builds on one; nullopt where a model has no
// estimate or no candidate.
std::vector<std::optional<OrientationAdvice>> NextOrientations(
    const std::vector<FreeModelResult>& results, const std::vector<FreeInterval>& intervals,
    const FreeContext& context);

// The largest uncovered region in the words of a hand (issue 37): "the largest region without a
// value is about -z (none within 90 deg; 50 % of the sphere empty): turn it so that -z points
// along the field (north and 60 deg down)" for a magnetometer (`dip_deg` the field's dip below
// the horizontal), "... so that -z points up" for an accelerometer. Empty for an empty gap.
std::string CoverageGapText(const CoverageGap& gap, SensorKind sensor, double dip_deg);

}  // namespace turncal
