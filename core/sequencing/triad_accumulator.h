#pragma once
// Streaming mean and covariance of one triad (Welford's update, vector form): constant memory
// however long the dwell, numerically stable for means far from zero (gravity with micro-g
// noise).

#include <Eigen/Core>
#include <cstdint>

#include "core/estimation/pose_record.h"

namespace turncal {

class TriadAccumulator {
 public:
  void Reset() { *this = TriadAccumulator(); }
  void Add(const Eigen::Vector3d& x) {
    ++count_;
    const Eigen::Vector3d delta = x - mean_;
    mean_ += delta / static_cast<double>(count_);
    m2_ += delta * (x - mean_).transpose();
  }
  std::int64_t count() const { return count_; }
  const Eigen::Vector3d& mean() const { return mean_; }
  // Sample covariance (n - 1 in the denominator); zero below two samples.
  Eigen::Matrix3d covariance() const {
    if (count_ < 2) return Eigen::Matrix3d::Zero();
    const Eigen::Matrix3d c = m2_ / static_cast<double>(count_ - 1);
    return 0.5 * (c + c.transpose());
  }
  TriadStats Stats() const {
    TriadStats s;
    s.mean = mean_;
    s.covariance = covariance();
    s.count = count_;
    return s;
  }

 private:
  std::int64_t count_ = 0;
  Eigen::Vector3d mean_ = Eigen::Vector3d::Zero();
  Eigen::Matrix3d m2_ = Eigen::Matrix3d::Zero();
};

}  // namespace turncal
