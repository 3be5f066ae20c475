#pragma once
// Streaming mean and covariance of one triad (Welford's update, vector form): constant memory
// however long the dwell, numerically stable for means far from zero (gravity with micro-g
// noise). A triad that holds its values (a magnetometer slower than the stream repeats each value
// until the next) is also accumulated over its fresh values only, and its statistics say so: its
// mean's white noise averages over values, not samples.

#include <Eigen/Core>
#include <cstdint>

#include "core/estimation/pose_record.h"

namespace turncal {

// Whether a triad's `samples` of which `values` were fresh (not a bit-identical repeat of the one
// before) held its values: at least three values, and a fifth of the samples or more repeats (a
// magnetometer at 50 Hz in a 100-Hz stream repeats half; chance repeats of all three axes of a
// noisy sensor are far rarer). A triad below its resolution that never changes has one value and
// is counted by its samples.
inline bool HeldRepeats(std::int64_t samples, std::int64_t values) {
  return values >= 3 && 5 * (samples - values) >= samples;
}

class TriadAccumulator {
 public:
  void Reset() { *this = TriadAccumulator(); }
  void Add(const Eigen::Vector3d& x) {
    all_.Add(x);
    if (fresh_.count == 0 || x != last_) fresh_.Add(x);
    last_ = x;
  }
  std::int64_t count() const { return all_.count; }
  // Whether the triad held its values (HeldRepeats over its samples and fresh values).
  bool held() const { return HeldRepeats(all_.count, fresh_.count); }
  // The independent count: values when held, else samples.
  std::int64_t independent() const { return held() ? fresh_.count : all_.count; }
  const Eigen::Vector3d& mean() const { return all_.mean; }
  // Sample covariance (n - 1 in the denominator; over the values when held); zero below two.
  Eigen::Matrix3d covariance() const { return held() ? fresh_.Covariance() : all_.Covariance(); }
  TriadStats Stats() const {
    TriadStats s;
    s.mean = all_.mean;
    s.covariance = covariance();
    s.count = all_.count;
    s.values = held() ? fresh_.count : 0;
    return s;
  }

 private:
  struct Welford {
    std::int64_t count = 0;
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    Eigen::Matrix3d m2 = Eigen::Matrix3d::Zero();
    void Add(const Eigen::Vector3d& x) {
      ++count;
      const Eigen::Vector3d delta = x - mean;
      mean += delta / static_cast<double>(count);
      m2 += delta * (x - mean).transpose();
    }
    Eigen::Matrix3d Covariance() const {
      if (count < 2) return Eigen::Matrix3d::Zero();
      const Eigen::Matrix3d c = m2 / static_cast<double>(count - 1);
      return 0.5 * (c + c.transpose());
    }
  };
  Welford all_;
  Welford fresh_;
  Eigen::Vector3d last_ = Eigen::Vector3d::Zero();
};

}  // namespace turncal
