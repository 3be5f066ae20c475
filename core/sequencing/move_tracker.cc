#include "core/sequencing/move_tracker.h"

#include <fmt/format.h>

#include <cmath>

namespace turncal {

bool MoveTrackerOptions::IsValid(std::string* error) const {
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  if (!(block_s > 0) || !std::isfinite(block_s)) return fail("move_block_s must be > 0");
  if (!(max_s > 0) || !std::isfinite(max_s)) return fail("move_max_s must be > 0");
  if (max_gap_samples < 0) return fail("the moves' gap must be >= 0 samples");
  return true;
}

namespace {

double SensorSeconds(const StillSample& s) {
  return std::isfinite(s.t_sensor_s) ? s.t_sensor_s : s.t_s();
}

std::optional<Eigen::Vector3d> Force(const StillSample& s) {
  if (!s.has(kTriadAcc)) return std::nullopt;
  return s.v[kTriadAcc];
}

}  // namespace

void MoveTracker::Start(const TablePose& from, const StillSample& last) {
  integrator_.reset();
  done_.reset();
  ended_ = false;
  if (!options_.enabled || !(period_s_ > 0) || from.is_rate() || !last.has(kTriadGyr)) return;
  integrator_.emplace(period_s_, options_.block_s);
  integrator_->Begin(SensorSeconds(last), last.v[kTriadGyr], Force(last));
  from_ = from;
}

void MoveTracker::Add(const StillSample& s) {
  if (shadow_) {
    // The same checks as a tracked move's, silently: a shadow that cannot go on is dropped.
    const std::uint32_t gap = s.lost_before + s.outliers_before;
    if (!s.has(kTriadGyr) || s.flagged_before > 0 ||
        gap > static_cast<std::uint32_t>(options_.max_gap_samples)) {
      shadow_.reset();
    } else {
      shadow_->Add(SensorSeconds(s), s.v[kTriadGyr], Force(s), static_cast<int>(gap) + 1);
      if (shadow_->duration_s() > options_.max_s) shadow_.reset();
    }
  }
  if (!tracking()) return;
  if (!s.has(kTriadGyr)) return Abort("a sample in it lacked the gyro");
  if (s.flagged_before > 0) {
    return Abort(
        fmt::format("{} flagged sample(s) in it (a saturated gyro loses angle)", s.flagged_before));
  }
  const std::uint32_t gap = s.lost_before + s.outliers_before;
  if (gap > static_cast<std::uint32_t>(options_.max_gap_samples)) {
    return Abort(fmt::format("{} samples in a row were lost in it (at most {} are bridged)", gap,
                             options_.max_gap_samples));
  }
  integrator_->Add(SensorSeconds(s), s.v[kTriadGyr], Force(s), static_cast<int>(gap) + 1);
  if (integrator_->duration_s() > options_.max_s) {
    Abort(fmt::format("it took longer than {:.0f} s (move_max_s)", options_.max_s));
  }
}

void MoveTracker::End(const TablePose& to) {
  if (!tracking()) return;
  if (to.is_rate()) return Abort("a rate segment came between");
  if (resumable_) shadow_ = *integrator_;
  done_ = integrator_->Finish(from_, to);
  integrator_.reset();
  ended_ = true;
}

bool MoveTracker::Resume() {
  if (!shadow_) {
    Abort("the still segment it led to was skipped");
    return false;
  }
  integrator_ = std::move(shadow_);
  shadow_.reset();
  done_.reset();
  ended_ = false;
  return true;
}

std::optional<MoveRecord> MoveTracker::TakeEnded() {
  shadow_.reset();
  std::optional<MoveRecord> out = std::move(done_);
  done_.reset();
  ended_ = false;
  if (out) ++moves_;
  return out;
}

void MoveTracker::Abort(const std::string& why) {
  const bool had = integrator_.has_value() || done_.has_value();
  shadow_.reset();
  integrator_.reset();
  done_.reset();
  ended_ = false;
  if (had && !why.empty()) {
    ++dropped_;
    last_drop_ = why;
  }
}

}  // namespace turncal
