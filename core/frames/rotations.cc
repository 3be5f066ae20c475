#include "core/frames/rotations.h"

namespace turncal {

const std::array<Mat3<double>, 24>& AxisAlignedRotations() {
  static const std::array<Mat3<double>, 24> all = [] {
    std::array<Mat3<double>, 24> out;
    int n = 0;
    // A signed permutation matrix is a rotation when its determinant is +1.
    const int perms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
    for (const auto& p : perms) {
      for (int signs = 0; signs < 8; ++signs) {
        Mat3<double> m = Mat3<double>::Zero();
        for (int row = 0; row < 3; ++row) m(row, p[row]) = (signs >> row & 1) ? -1.0 : 1.0;
        if (m.determinant() > 0) out[n++] = m;
      }
    }
    return out;
  }();
  return all;
}

Mat3<double> NearestAxisAlignedRotation(const Mat3<double>& c) {
  const auto& all = AxisAlignedRotations();
  int best = 0;
  double best_score = -1e300;
  for (int i = 0; i < static_cast<int>(all.size()); ++i) {
    const double score = (c.transpose() * all[i]).trace();
    if (score > best_score) {
      best_score = score;
      best = i;
    }
  }
  return all[best];
}

}  // namespace turncal
