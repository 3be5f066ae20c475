#pragma once
// Has the bias settled in a chamber's soak (issue 36)? The sensor's temperature stopping is not
// enough: a bias may relax for minutes after the die has settled (thermal gradients inside the
// package, stress relaxation). While the table holds a pose, the output's mean over the first
// half of the soak window and over the second half must agree on every axis of every triad
// within what white noise and the class's own bias wander allow (the stillness detector's
// HalvesDriftLimit: z sqrt(sigma^2 (1/n1 + 1/n2) + the wander's halves variance)). Motion clears
// the window: a pose after a move is watched for the whole window again.

#include <Eigen/Core>

#include <array>
#include <deque>
#include <functional>
#include <string>

#include "core/sequencing/stillness.h"

namespace turncal {

// The limit on a triad's axis for the difference of two halves' means of n1 and n2 samples, in
// the triad's unit; <= 0: the axis is not checked.
using HalvesLimit = std::function<double(int triad, int axis, double n1, double n2)>;

class BiasSettleTracker {
 public:
  // One still sample (host seconds, increasing): summed into 0.1-s bins, those older than the
  // window dropped.
  void Add(const StillSample& s, double window_s);
  void Clear() { bins_.clear(); }
  // Settled, or why not ("the bias still moves: acc z changed by 2.1e-03 between the halves of
  // the last 60 s (within 4.0e-04 when settled)"); false until the bins span 80 % of the window.
  bool Settled(double window_s, const HalvesLimit& limit, std::string* why) const;
  double span_s() const;

 private:
  struct Bin {
    double t0_s = 0.0, t1_s = 0.0;  // the first and the last sample's time
    std::array<Eigen::Vector3d, 3> sum{Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(),
                                       Eigen::Vector3d::Zero()};
    std::array<double, 3> count{0.0, 0.0, 0.0};
  };
  std::deque<Bin> bins_;
};

}  // namespace turncal
