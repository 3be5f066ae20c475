#pragma once
// The position sequencer (issue "Position sequencer"; DESIGN.md "Pose sources"): turns a stream
// of samples plus pose commands into PoseRecords -- the only input the calibrator trusts -- and
// says why whenever it does not.
//
// Sources:
//   announced  Announce(): the controller says the table is at a pose. The sequencer waits for
//              the sensor to be still (up to still_timeout_s), collects dwell_s of samples that
//              arrived after the announcement, and answers CAPTURED or REJECTED with a reason.
//              Replayed capture events take the same path.
//   rate       Announce() with a rate segment (TablePose::rate_axis): the table turns about one
//              axis at a constant rate. The gyro alone decides (core/sequencing/rate_steady.h):
//              once its rate is steady, the sequencer collects whole revolutions at the announced
//              rate, at least dwell_s, of the gyro triad only, and rejects the segment if the
//              rate is not steady throughout.
//   schedule   SetSchedule(): poses in order, assigned to the still segments of the stream;
//              a segment shorter than the dwell, or whose mean does not fit the next pose, is
//              skipped with a reason; the end says whether the count fitted.
//
// A sample is used only after it has been inside `window` consecutive still windows and the
// window has been still for settle_guard_s more (the detector's look-ahead), so motion that
// starts just after a sample cannot reach the record: on motion the pose is rejected (announced)
// or the segment ends (schedule) and nothing from the moving window is used.
//
// Samples with saturation, clipping or status-error flags, samples missing a triad the noise
// profile uses, isolated outliers (StillnessDetector::IsOutlier) and lost samples (counter or
// device-clock gaps) are excluded and counted against the pose whose window they fall in; more
// than max_bad_fraction flagged and outliers, or more than max_lost_fraction lost, rejects the
// pose. Lost samples are apart: a checksum that fails on line noise loses samples at random,
// which leaves the mean of the rest unbiased (only its n smaller); flags and outliers say the
// device or the table misbehaved. Memory is fixed once the noise is known: the
// detector's window and three Welford accumulators, whatever the dwell.
//
// Pure computation: time comes from the samples and from Tick(). A sample's time is when it was
// sent, on the host clock: its receive time, or earlier when its device clock shows it was read
// late, in a backlog (HostClock).

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/estimation/pose_record.h"
#include "core/sequencing/bias_settle.h"
#include "core/sequencing/host_clock.h"
#include "core/sequencing/move_tracker.h"
#include "core/sequencing/pose_check.h"
#include "core/sequencing/rate_steady.h"
#include "core/sequencing/sample.h"
#include "core/sequencing/soak.h"
#include "core/sequencing/stillness.h"
#include "core/sequencing/triad_accumulator.h"

namespace turncal {

struct SequencerOptions {
  double dwell_s = 3.0;            // of samples to average per pose
  double settle_guard_s = 0.5;     // stillness required beyond one window before samples count
  double still_timeout_s = 20.0;   // from the announcement until collection starts
  double max_bad_fraction = 0.02;  // flagged + outliers over the dwell
  double max_lost_fraction = 0.5;  // lost over the dwell (counter or device-clock gaps)
  double pose_check_false_alarm = 1e-6;
  double progress_step = 0.1;  // a progress event every this fraction of the dwell
  // Free mode (SetFree): an interval averages its whole still segment, at least dwell_s and at
  // most this long ([sequencer] free_max_dwell_s).
  double free_max_dwell_s = 60.0;
  StillnessOptions stillness;
  // Rate segments (an announced pose with a rate axis): the steadiness of the gyro's rate.
  RateSteadyOptions rate_steady;
  NoiseMeterOptions noise_meter;
  // The moves between static poses (core/sequencing/move_tracker.h).
  MoveTrackerOptions moves;
  std::optional<NoiseProfile> noise;  // configured; measured at start-up when absent
  bool IsValid(std::string* error) const;
};

enum class SequencerEventKind {
  kNoiseMeasured,   // the noise profile is known (reason: its description)
  kNoiseRetry,      // a start-up measurement failed (reason), another begins
  kPoseStarted,     // announced, or the next scheduled pose
  kCollecting,      // still: samples now count
  kProgress,        // collected / needed
  kCaptured,        // record
  kRejected,        // reason
  kSegmentSkipped,  // schedule mode: a still segment not used (reason)
  kScheduleEnd,     // schedule mode, at Finish: whether the count fitted (reason)
  kSoakWaiting,     // announced in a soak: the pose waits for the temperature to settle (reason)
};
const char* ToString(SequencerEventKind kind);  // "POSE_CAPTURED", ...

struct SampleCounts {
  std::int64_t used = 0;
  std::int64_t flagged = 0;   // saturation, clipping, status error, missing triad
  std::int64_t outliers = 0;  // isolated samples far from the window's median
  std::int64_t lost = 0;      // counter or device-clock gaps
  std::int64_t bad() const { return flagged + outliers + lost; }
  // Of every sample the dwell spanned (used + bad).
  double bad_fraction() const { return Fraction(flagged + outliers); }
  double lost_fraction() const { return Fraction(lost); }
  double Fraction(std::int64_t n) const {
    const auto all = used + bad();
    return all > 0 ? static_cast<double>(n) / static_cast<double>(all) : 0.0;
  }
};

struct SequencerEvent {
  SequencerEventKind kind = SequencerEventKind::kPoseStarted;
  double t_s = 0.0;  // host time of the sample (or tick) that caused it
  int index = -1;    // pose index (announced: as given; schedule: position in the schedule)
  TablePose pose;
  std::int64_t collected = 0, needed = 0;
  SampleCounts counts;
  std::optional<PoseRecord> record;
  std::string reason;
};

// The current calibration's prediction of a triad's mean at a pose (triad kTriadAcc or
// kTriadMag), or nullopt when there is none to check against.
using PosePredictor = std::function<std::optional<TriadPrediction>(const TablePose&, int triad)>;

struct Announcement {
  int index = -1;
  TablePose pose;
  std::int64_t t_host_ns = 0;
  std::optional<double> dwell_s;  // overrides the configured dwell for this pose
};

class Sequencer {
 public:
  using Sink = std::function<void(const SequencerEvent&)>;
  // Sees every sample left out ("flagged", "incomplete", "outlier"), for logs and tests.
  using ExclusionObserver = std::function<void(const StillSample&, const char* why)>;
  // `options` must be valid (SequencerOptions::IsValid).
  Sequencer(const SequencerOptions& options, Sink sink);

  // Announced mode. A pose still pending is rejected ("superseded"). False with *error when the
  // announcement cannot be taken (schedule mode, bad dwell).
  bool Announce(const Announcement& announcement, std::string* error);
  // Schedule mode; only before the first announcement.
  bool SetSchedule(std::vector<TablePose> poses, std::string* error);
  // Free mode (issue 22, a tumble without a table): no poses at all; every still segment of at
  // least the dwell becomes a record (its pose left at TablePose{}, index counting up), averaged
  // over the whole segment up to free_max_dwell_s, with the move from the previous one. Only
  // before the first announcement.
  bool SetFree(std::string* error);
  bool free_mode() const { return free_; }
  // A climate chamber's soak (core/sequencing/soak.h): announced poses wait until the sensor's
  // temperature has settled (nullopt: a ramp, or no chamber; poses are taken at once).
  // A new set-point (or none) watches the bias again.
  void SetSoak(std::optional<SoakOptions> soak) {
    if (!soak || !soak_ || soak->setpoint_c != soak_->setpoint_c) {
      bias_settled_ = false;
      bias_settle_.Clear();
    }
    soak_ = std::move(soak);
  }
  const std::optional<SoakOptions>& soak() const { return soak_; }
  const SoakTracker& soak_tracker() const { return soak_tracker_; }
  void SetPredictor(PosePredictor predictor) { predictor_ = std::move(predictor); }
  void SetExclusionObserver(ExclusionObserver observer) { excluded_ = std::move(observer); }

  void Push(const Sample& sample);
  void Push(StillSample sample);
  // Time passes without samples (a live device went quiet): timeouts fire.
  void Tick(std::int64_t now_ns);
  // End of input: a pending pose is rejected; schedule mode reports how the count fitted.
  void Finish(std::int64_t now_ns);

  bool busy() const { return state_ == State::kWaiting || state_ == State::kCollecting; }
  const NoiseProfile* noise() const { return detector_ ? &detector_->profile() : nullptr; }
  // The sensor clock of the records' t_sensor_start/t_sensor_end for a sample with device time
  // `t_device_s` (the device clock continued across its resets); nullopt before the sequencer has
  // seen a device time.
  std::optional<double> SensorTimeOfDevice(double t_device_s) const {
    if (!sensor_last_device_s_) return std::nullopt;
    return t_device_s + sensor_offset_s_;
  }
  const StillnessDetector* detector() const { return detector_.get(); }
  // Over the whole stream.
  const SampleCounts& totals() const { return totals_; }
  std::int64_t captured() const { return captured_; }
  std::int64_t rejected() const { return rejected_; }
  // The moves handed to records, and those dropped with the last reason.
  const MoveTracker& moves() const { return moves_; }
  const SequencerOptions& options() const { return options_; }
  // The latest pose announced or scheduled (none before the first): where the table is or goes.
  std::optional<TablePose> announced() const {
    return has_pose_ ? std::optional<TablePose>(pose_) : std::nullopt;
  }
  // Scales the bias wander the stillness and creep tests allow for on one triad (kTriadAcc,
  // kTriadGyr, kTriadMag): the drift's strength the calibrator identified, as a sigma factor.
  void SetDriftScale(int triad, double scale);
  // The same from a calibrator's identification, recorded in the noise profile (noise()).
  void SetIdentifiedDrift(int triad, const IdentifiedDrift& identified);

 private:
  enum class State { kIdle, kWaiting, kCollecting, kSegmentDone, kScheduleDone };
  void Emit(SequencerEventKind kind, double t_s, std::string reason = {},
            const PoseRecord* record = nullptr);
  void StartDetector(const NoiseProfile& profile, double t_s);
  void Feed(const StillSample& s);
  void FeedRate(const StillSample& s);
  void StartCollecting(const StillSample& first);
  // In a soak: whether the announced pose may start collecting (else a kSoakWaiting event now
  // and then, and soak_why_ says why).
  bool SoakSettled(double t_s);
  void Commit(const StillSample& s);
  void Complete(double t_s);
  void Reject(double t_s, std::string reason);
  void SkipSegment(double t_s, std::string reason);
  void NextScheduled(double t_s);
  // Waits for the table at `pose` (a free interval: an unknown one), schedule entry
  // next_scheduled_.
  void WaitForPose(const TablePose& pose);
  void Accept(StillSample s);
  // Sample periods from the last sample to `s` by the device's counter or clock (negative:
  // backwards); nullopt when neither tells.
  std::optional<std::int64_t> StepsAhead(const StillSample& s) const;
  std::uint32_t CountLost(const StillSample& s);
  void CheckTimeout(std::int64_t now_ns);
  void Interrupt(double t_s, const std::string& why);
  bool scheduled() const { return !schedule_.empty(); }

  SequencerOptions options_;
  Sink sink_;
  PosePredictor predictor_;
  ExclusionObserver excluded_;
  NoiseMeter meter_;
  std::unique_ptr<StillnessDetector> detector_;
  std::array<double, 3> drift_scale_{1.0, 1.0, 1.0};
  std::array<std::optional<IdentifiedDrift>, 3> identified_;
  std::int64_t required_run_ = 0;

  State state_ = State::kIdle;
  std::vector<TablePose> schedule_;
  std::size_t next_scheduled_ = 0;
  bool free_ = false;
  std::int64_t free_max_needed_ = 0;
  std::int64_t extra_segments_ = 0, skipped_segments_ = 0;
  int index_ = -1;
  TablePose pose_;
  bool has_pose_ = false;
  std::int64_t t_announce_ns_ = 0;
  bool announced_ = false;  // announced mode (t_announce_ns_ meaningful, timeouts apply)
  bool seen_motion_after_schedule_ = false;
  bool rate_mode_ = false;  // the current pose is a rate segment
  std::unique_ptr<RateSteadiness> rate_;
  double dwell_s_ = 0.0;
  std::int64_t needed_ = 0;
  SampleCounts counts_;
  std::int64_t next_progress_ = 0;
  std::array<TriadAccumulator, 3> acc_;
  std::array<TriadAccumulator, 3> first_half_;  // of the dwell, for the creep check
  // The temperature over the dwell: sums about the first sample's (temp_ref_), and the extremes.
  double temp_ref_ = 0.0, temp_sum_ = 0.0, temp_sum2_ = 0.0, temp_min_ = 0.0, temp_max_ = 0.0;
  std::int64_t temp_n_ = 0;
  std::int64_t t_first_ns_ = 0, t_last_ns_ = 0;
  double t_first_sensor_s_ = 0.0, t_last_sensor_s_ = 0.0;

  // Stream state.
  std::optional<StillSample> held_;  // a possible outlier waiting for its successor
  std::optional<StillSample>
      jumped_;  // its counter jumped: corrupt, or a real gap? (its successor)
  std::uint32_t pending_lost_ = 0, pending_flagged_ = 0, pending_outliers_ = 0;
  std::optional<std::uint32_t> last_counter_;
  std::optional<double> last_device_s_;
  std::optional<std::int64_t> last_host_ns_;  // the last sample's sending time (HostClock)
  std::optional<std::int64_t> last_read_ns_;  // and when it was read
  // The sensor clock (SensorTime): the device clock plus an offset that changes only where the
  // device clock resets or jumps, so that drift is timed as the sensor lived it whatever the
  // host's pace (a replay, a simulator running faster than real time).
  double SensorTime(const StillSample& s);
  std::optional<double> sensor_last_s_, sensor_last_device_s_;
  double sensor_last_host_s_ = 0.0;
  double sensor_offset_s_ = 0.0;
  HostClock clock_;  // device time -> host time of sending
  StillFinding last_motion_;
  double last_motion_t_s_ = -1.0;
  std::optional<SoakOptions> soak_;
  SoakTracker soak_tracker_;
  BiasSettleTracker bias_settle_;  // the output at rest while a soak's bias is watched
  bool bias_settled_ = false;      // the bias has settled at this set-point
  std::string soak_why_;           // why the pending pose waits for the soak (empty: it does not)
  double soak_event_t_s_ = -1e9;   // the latest kSoakWaiting event
  std::string last_noise_failure_;
  SampleCounts totals_;
  std::int64_t captured_ = 0, rejected_ = 0;
  MoveTracker moves_;
  StillSample last_committed_;
  // The accepted samples, outliers included, until the detector's delayed stream reaches them;
  // what was flagged or lost before each (at most a window and a held sample).
  // A ring of fixed capacity (two detector windows), allocated once with the detector.
  std::vector<StillSample> move_ring_;
  std::size_t move_head_ = 0, move_size_ = 0;
  std::uint32_t move_lost_ = 0, move_flagged_ = 0;
  std::uint64_t accepted_ = 0;
};

}  // namespace turncal
