#pragma once
// The truth of a free model (core/modeling/free_model.h) for a simulated session (issue 22): the
// simulator's truths are the pose models' (accel12/13, mag13, gyro12/21), and a free model
// describes the same sensor in its own frame -- accel9's triad frame fixed by its upper-
// triangular T K, gyro9's in that frame, the magnetometer's field scaled to the magnitude the
// calibration assumes. For a sensor a = G f + b:
//   accel9: T K is the upper-triangular C with C^T C = (G G^T)^-1 (so C G = Q_a is a rotation);
//   gyro9: T K = Q_a G_w^-1, gyro9g's B = B_g Q_a^T (the g-sensitivity against accel9's force);
//   magellipsoid: S = (F / |B|) (G G^T)^-1/2, F the magnitude the calibration assumes (the
//   reference's, or 1 when not known);
//   accmag: accel9's and magellipsoid's, R = Q_a (S G |B| / F)^T and the reference's dip.
// The biases are the turn-on biases plus the wander averaged over `bias_window` (session time:
// a calibration with a drift model estimates the bias over its latest interval), or without one
// over the dwells (what a calibration that takes each interval's offset as independent finds).

#include <Eigen/Core>
#include <optional>
#include <string>

#include "core/modeling/free_model.h"
#include "sim/capture.h"

namespace turncal::sim {

// False with a message for a free model the capture's truths cannot describe (mag22, a gyro
// model without a gyro truth).
bool FreeTruth(const SimCapture& capture, const std::string& free_model, const FreeContext& context,
               const std::optional<TimeWindow>& bias_window, Eigen::VectorXd* truth,
               std::string* error);

}  // namespace turncal::sim
