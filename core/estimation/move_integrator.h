#pragma once
// The raw gyro integrated into a move's blocks (core/estimation/move_record.h), for the
// sequencer (core/sequencing/move_tracker.h) and the simulator alike.
//
// Each interval between consecutive samples (each the rate at its instant: a device's filtered,
// band-limited rate sampled) turns the sensor by
//   d = (w0 + w1) dt / 2 + dt^2 / 6 (w0 x w1),
// the trapezoid rule and a second-order term: the interval's own coning (dt^2 / 12, the rate
// taken to change linearly) and as much again for the trapezoid's curvature error, which
// telescopes for a fixed axis but, composed in a turning frame, leaves dt^2 / 12 times the
// integral of w x dw/dt. The intervals of a block compose to first order as phi += d + phi x d / 2
// (Bortz). Measured at the truth over 3-axis moves (tests/sim/gyro_move_test.cc, 100 Hz): the
// trapezoid alone missed the table's turn by up to 7e-5 rad, with dt^2 / 12 by 3.5e-5, with
// dt^2 / 6 by 9e-7 (500 Hz: 2e-7). A block is `block_s` of whole sample periods (at least one);
// the last one may be shorter. The raw accelerometer's mean over a block (trapezoid) goes with it,
// for a g-sensitivity.
//
// A step in the angular acceleration between two samples (a table whose rate profile starts with
// a jump in acceleration) is missed by up to dt^2 / 8 times the step, dt^2 / 12 on average and of
// one sign: 1e-5 rad at 100 Hz for 1 rad/s^2. Tables limit the jerk; the simulator's moves do.
//
// `period_s` is the device's nominal sample period: the integral is in the time the samples are
// paced by, so a sample clock off by e (a crystal's 20 ppm) makes the moves' scale factors off by
// e (the rate segments, averages, do not have it). Pure computation.

#include <Eigen/Core>
#include <optional>

#include "core/estimation/move_record.h"

namespace turncal {

class MoveIntegrator {
 public:
  MoveIntegrator(double period_s, double block_s);

  // The first sample (on the sensor's clock), its rate and, when the device sends one, its
  // specific force.
  void Begin(double t_s, const Eigen::Vector3d& gyr_radps,
             const std::optional<Eigen::Vector3d>& acc_mps2);
  // The next sample, `periods` sample periods after the last one (1; more across lost samples,
  // which the trapezoid bridges).
  void Add(double t_s, const Eigen::Vector3d& gyr_radps,
           const std::optional<Eigen::Vector3d>& acc_mps2, int periods = 1);
  bool begun() const { return begun_; }
  double duration_s() const;  // of the intervals added so far
  std::int64_t samples() const { return samples_; }
  std::size_t blocks() const { return record_.block_s.size() + (in_block_ > 0 ? 1 : 0); }

  // The record from `from` to `to` (the partial last block included); the integrator is empty
  // afterwards.
  MoveRecord Finish(const TablePose& from, const TablePose& to);
  void Clear();

 private:
  void CloseBlock();

  double period_s_;
  int per_block_;
  bool begun_ = false;
  bool with_force_ = true;
  MoveRecord record_;
  Eigen::Vector3d gyr_last_ = Eigen::Vector3d::Zero();
  std::optional<Eigen::Vector3d> acc_last_;
  Eigen::Vector3d phi_ = Eigen::Vector3d::Zero(), force_sum_ = Eigen::Vector3d::Zero();
  int in_block_ = 0;  // sample periods in the open block
  std::int64_t samples_ = 0, bridged_ = 0;
};

}  // namespace turncal
