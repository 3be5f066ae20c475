#pragma once
// Pose designs: the classic 26-position cube, random directions, and the degenerate turn about
// one axis (for the observability analysis, plans and the Monte Carlo checks).

#include <random>
#include <vector>

#include "core/frames/table_pose.h"

namespace turncal {

// n table poses whose "down" directions are uniform on the sphere and psi uniform.
std::vector<TablePose> RandomPoses(int n, std::mt19937_64* rng);
// The classic 26-position design: down along the 6 faces, 12 edges and 8 corners of a cube,
// with psi cycling through 0, 90, 180, 270 degrees so the heading is excited.
std::vector<TablePose> CubePoses26();
// All poses turning about the table's outer (z) axis only: the degenerate design.
std::vector<TablePose> AboutZPoses(int n);

}  // namespace turncal
