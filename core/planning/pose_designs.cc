#include "core/planning/pose_designs.h"

#include <cmath>

namespace turncal {

std::vector<TablePose> RandomPoses(int n, std::mt19937_64* rng) {
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::vector<TablePose> poses;
  for (int i = 0; i < n; ++i) {
    Eigen::Vector3d d;
    do {
      d = Eigen::Vector3d(uniform(*rng), uniform(*rng), uniform(*rng));
    } while (d.norm() > 1.0 || d.norm() < 0.1);
    poses.push_back(PoseWithDownAlong(d, M_PI * uniform(*rng)));
  }
  return poses;
}

std::vector<TablePose> CubePoses26() {
  std::vector<TablePose> poses;
  int k = 0;
  for (int x = -1; x <= 1; ++x)
    for (int y = -1; y <= 1; ++y)
      for (int z = -1; z <= 1; ++z) {
        if (x == 0 && y == 0 && z == 0) continue;
        poses.push_back(PoseWithDownAlong(Eigen::Vector3d(x, y, z), (k++ % 4) * M_PI / 2));
      }
  return poses;
}

std::vector<TablePose> AboutZPoses(int n) {
  std::vector<TablePose> poses;
  for (int i = 0; i < n; ++i) poses.push_back(TablePose{0.0, 0.0, 2 * M_PI * i / n});
  return poses;
}

}  // namespace turncal
