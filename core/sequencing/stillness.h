#pragma once
// Stationarity detection on the live stream (issue "Position sequencer"): a sliding window over
// the accelerometer, gyro and (when present) magnetometer whose thresholds come from the sensor's
// noise -- measured at start-up (NoiseMeter) or configured (NoiseProfileForClass) -- and a chosen
// false-alarm probability, never from magic constants. Every verdict carries its reason.
//
// Per window of W samples and per axis, three tests (docs/SEQUENCER.md):
//   variance  s^2 / sigma^2 below the chi^2_{W-1}/(W-1) quantile (F_{W-1,nu} when sigma was
//             measured from nu degrees of freedom): vibration, oscillation, rotation noise;
//   drift     mean of the newer half minus mean of the older half within z sigma sqrt(4/W)
//             (Student's t with nu dof when measured): slow tilts and turns;
//   rate      (gyro only) |mean - bias| within z sqrt(sigma^2/W + sigma_bias^2) plus the allowed
//             bias drift: any turn of the table.
// Isolated samples far from the window's median (k robust sigmas, sigma = max(1.4826 MAD,
// noise)) are outliers (bit flips that passed a checksum, a spike); a run of two or more is a
// real change and goes into the window.
//
// Pure computation; the window is allocated once (W = window_s x rate), so memory does not grow.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "core/estimation/bias_drift.h"
#include "core/estimation/sensor_class.h"
#include "core/sequencing/sample.h"

namespace turncal {

inline constexpr int kTriadAcc = 0;
inline constexpr int kTriadGyr = 1;
inline constexpr int kTriadMag = 2;
const char* TriadName(int triad);    // "acc", "gyr", "mag"
int TriadOfSensor(SensorKind kind);  // kTriadAcc, kTriadGyr or kTriadMag
const char* TriadUnit(int triad);    // "m/s^2", "rad/s", "(device unit)"

// A sample as the detector and sequencer keep it: fixed size, no strings.
struct StillSample {
  std::int64_t t_host_ns = 0;
  std::optional<double> t_device_s;
  std::optional<std::uint32_t> counter;
  std::array<Eigen::Vector3d, 3> v{Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(),
                                   Eigen::Vector3d::Zero()};
  std::uint8_t present = 0;  // bit i: triad i
  double temp_c = std::numeric_limits<double>::quiet_NaN();
  std::uint32_t flags = 0;  // SampleFlag bits
  // Samples that did not make it into the stream just before this one (the sequencer attaches
  // them here so they are counted against the pose whose window this sample ends up in).
  std::uint32_t lost_before = 0, flagged_before = 0, outliers_before = 0;
  // The sequencer's sensor clock (Sequencer: the device clock, kept continuous across resets;
  // the host clock for devices without one): what bias drift evolves in.
  double t_sensor_s = std::numeric_limits<double>::quiet_NaN();
  // The sequencer's count of the samples it accepted (stream order), for the moves' own queue.
  std::uint64_t seq = 0;

  bool has(int triad) const { return (present >> triad) & 1u; }
  double t_s() const { return static_cast<double>(t_host_ns) * 1e-9; }
};
StillSample ToStillSample(const Sample& sample);

// A triad's bias wander as the calibrator identified it from the session's poses
// (core/estimation/drift_identify.h): the configured drift times the scale the solve used.
struct IdentifiedDrift {
  BiasDrift drift;
  double scale = 1.0;  // on the configured drift's sigma
  int poses = 0;       // identified from this many poses
};

// What the detector knows of the sensor's noise.
struct NoiseProfile {
  // Per-sample 1 sigma per axis of each triad; absent: the triad is not used for stillness.
  std::array<std::optional<Eigen::Vector3d>, 3> sigma;
  Eigen::Vector3d gyr_bias_radps = Eigen::Vector3d::Zero();
  double gyr_bias_sigma_radps = 0.0;  // how well the bias is known (1 sigma)
  // The sensor's temperature while the bias was measured (deg C; NaN: not known or not reported).
  double gyr_bias_temp_c = std::numeric_limits<double>::quiet_NaN();
  double rate_hz = 0.0;                   // sample rate
  std::optional<double> device_period_s;  // device-clock sample period (for gap counting)
  // Degrees of freedom of the sigma estimates (the samples'); infinite when configured from a
  // datasheet.
  double sigma_dof = std::numeric_limits<double>::infinity();
  // Per triad, the lag-one correlation of its values (of the axis that correlates most; 0: white
  // or not measured). A device that filters its samples (a 1-kHz stream, a magnetometer behind
  // a low-pass) sends correlated values, and n of them estimate sigma as n (1 - rho^2) /
  // (1 + rho^2) independent ones would (first-order autoregressive noise).
  std::array<double, 3> lag_one = {0.0, 0.0, 0.0};
  // The degrees of freedom of triad t's sigma: sigma_dof with its values' correlation allowed for.
  double TriadDof(int t) const;
  std::string source;  // e.g. "measured over 1.00 s (100 samples)"
  // The host times of the measurement's first and last sample, s (absent: a datasheet's profile):
  // free mode leaves the magnetometer's values there out of its fit in motion, whose check weighs
  // the other values with this sigma (an F test needs the two independent).
  std::optional<std::pair<double, double>> measured_host_s;
  // Per triad, the bias wander identified from the poses (absent until a calibrator has); the
  // stillness tests allow for it, and it is kept with the profile across restarts.
  std::array<std::optional<IdentifiedDrift>, 3> identified_drift;

  bool IsValid(std::string* error) const;
  std::string Describe() const;
};

// From a datasheet class (SENSORS.md) at `rate_hz`: white noise density x sqrt(rate / 2) with
// the quantisation step / sqrt(12) added in quadrature; gyro bias unknown (its turn-on 1 sigma).
NoiseProfile NoiseProfileForClass(const SensorClass& sensor, double rate_hz, bool use_mag);

struct NoiseMeterOptions {
  double duration_s = 1.0;  // of one measurement attempt
  int sub_windows = 4;      // the attempt is checked for stillness by comparing its parts
  double false_alarm = 1e-4;
  double gyr_bias_limit_radps = 0.1;  // a larger gyro mean is a turning table, not a bias
  double outlier_k = 5.0;
  double max_outlier_fraction = 0.05;
  bool use_mag = true;
  bool IsValid(std::string* error) const;
};

// Measures the noise profile from the first `duration_s` of the stream, assuming the table is at
// rest -- and checking it: the parts' variances and means must agree within their sampling
// distributions and the gyro mean must be a plausible bias. Isolated outliers (beyond
// outlier_k robust sigmas of the attempt's median) are left out first. A failed attempt says
// why; the caller starts another on the following samples. The attempt's samples are kept until
// it ends (duration x rate of them; start-up only).
class NoiseMeter {
 public:
  enum class Status { kCollecting, kMeasured, kRejected };
  explicit NoiseMeter(const NoiseMeterOptions& options);
  Status Add(const StillSample& sample);
  const NoiseProfile& profile() const { return profile_; }
  const std::string& failure() const { return failure_; }
  std::int64_t samples() const { return static_cast<std::int64_t>(samples_.size()); }
  std::int64_t outliers() const { return outliers_; }
  void Restart();

 private:
  Status Finish();
  // Finish's steps: the triads most samples carry (bit i: triad i); the samples kept (those with
  // every present triad and no isolated outlier); their accumulation into the attempt's parts
  // (counting outliers_); one triad's noise and the stillness tests of its parts (false with the
  // reason); the sample rate (false with the reason).
  std::uint8_t PresentTriads() const;
  std::vector<char> KeptSamples(std::uint8_t present) const;
  void Accumulate(std::uint8_t present, const std::vector<char>& keep, std::int64_t* t_first_ns,
                  std::int64_t* t_last_ns, std::int64_t* n);
  bool TriadNoise(int t, NoiseProfile* profile, std::string* why) const;
  bool MeasureRate(NoiseProfile* profile, std::string* why) const;
  NoiseMeterOptions options_;
  std::vector<StillSample> samples_;
  std::int64_t outliers_ = 0;
  // One triad's values in a part: their count, mean and sum of squared deviations (Welford).
  // With the sums of the lag-one products of consecutive values, about the part's first value
  // (no cancellation at a large mean): the values' correlation.
  struct Moments {
    std::int64_t n = 0;
    Eigen::Vector3d mean = Eigen::Vector3d::Zero(), m2 = Eigen::Vector3d::Zero();
    Eigen::Vector3d ref = Eigen::Vector3d::Zero(), last = Eigen::Vector3d::Zero();
    Eigen::Vector3d lag = Eigen::Vector3d::Zero(), head = Eigen::Vector3d::Zero(),
                    tail = Eigen::Vector3d::Zero();
    std::int64_t pairs = 0;
    void Add(const Eigen::Vector3d& v);
    // The sum of the lag-one products of deviations from the part's mean, per axis.
    Eigen::Vector3d LagOneSum() const;
  };
  // Per triad: every sample's value, and each value once (`fresh`: a triad slower than the
  // stream, a 50-Hz magnetometer in a 100-Hz stream, repeats its last value; counted twice, its
  // pairs make the scatter about a part's mean (n - 2) / (n - 1) of the variance's, 4 % low in a
  // part of 25, and a fit checked against it leans to too large a chi^2).
  struct Part {
    std::int64_t n = 0;
    std::array<Moments, 3> all, fresh;
  };
  // The moments TriadNoise measures triad `t` with: each value once when the triad repeats held
  // values and every part still has three, else every sample's (a sensor whose noise is below its
  // resolution repeats by chance).
  bool CountsHeldOnce(int t) const;
  const Moments& Of(const Part& p, int t) const;
  // Triad t's lag-one correlation per axis, pooled over the parts.
  Eigen::Vector3d LagOne(int t) const;
  // Triad t's steady drift per axis: the slope of the line through the parts' means (each
  // weighted by its count) per part; zero with fewer than three parts.
  Eigen::Vector3d Drift(int t) const;
  std::vector<Part> parts_;
  NoiseProfile profile_;
  std::string failure_;
};

struct StillnessOptions {
  double window_s = 0.5;
  // Probability that one test on one axis calls a still window moving (per evaluation).
  double false_alarm = 1e-8;
  double outlier_k = 5.0;  // robust sigmas for an isolated outlier
  // Gyro bias change allowed after the bias was taken (instability; temperature below).
  double gyr_bias_drift_radps = 2e-3;
  // The gyro bias's temperature coefficient (1 sigma over devices, rad/s per degC; the station
  // takes its sensor class's): the rate test also allows kTempcoSigmas times it per degC the
  // sensor's temperature has moved from where the bias was measured (at start-up, then at each
  // captured static pose, StillnessDetector::TrackGyroBias). In a chamber ramping 40 degC
  // an industrial gyro's bias moves ~3.5e-3 rad/s, more than the fixed allowance: without this
  // every static pose after that read as turning (issue 36: gyro12 over temperature lost every
  // static pose after the first such rejection in 164 of 200 simulated sessions).
  double gyr_bias_tempco_radps_per_c = 0.0;
  static constexpr double kTempcoSigmas = 4.0;
  // The bias wander of each triad (kTriadAcc, kTriadGyr, kTriadMag) that the halves' drift tests
  // allow for besides the white noise: within a dwell a sensor's own drift looks like a slowly
  // creeping table, and a consumer accelerometer's (0.02 m/s^2, tau 100 s) moves the halves of a
  // 3 s dwell twice as far apart as its white noise does. Zero (the default): white noise only.
  std::array<BiasDrift, 3> bias_drift{};
  bool IsValid(std::string* error) const;
};

// Why a window is not still (kind kNone when it is).
struct StillFinding {
  enum Kind { kNone, kFilling, kVariance, kDrift, kRate };
  Kind kind = kNone;
  int triad = 0, axis = 0;
  double value = 0.0, limit = 0.0;
  std::string Describe() const;
};

class StillnessDetector {
 public:
  StillnessDetector(const NoiseProfile& profile, const StillnessOptions& options);

  int window() const { return w_; }
  // True when `sample` lies more than outlier_k robust sigmas from the window's median on any
  // axis of a profiled triad (false while the window fills). Median and MAD are taken over at
  // most kMedianSamples samples evenly spread over the window, every window/4 pushes.
  static constexpr std::size_t kMedianSamples = 128;
  bool IsOutlier(const StillSample& sample);
  // Adds the sample and evaluates the window ending at it; true when the window is full and
  // still. When the window was full, *evicted receives the sample that left and *has_evicted
  // is set.
  bool Push(const StillSample& sample, StillSample* evicted, bool* has_evicted);
  // Consecutive still verdicts up to the last Push.
  std::int64_t still_run() const { return still_run_; }
  const StillFinding& finding() const { return finding_; }
  // What the rate test allows for the gyro bias's move with temperature since it was measured.
  double TemperatureAllowance() const;
  // A captured static pose's gyro mean (and the temperature over it, NaN: none) becomes the rate
  // test's bias: the bias follows the sensor through a chamber's ramp (and its slow wander)
  // instead of staying the start-up measurement's.
  void TrackGyroBias(const Eigen::Vector3d& mean_radps, double temp_c);
  // Forgets the window (after a gap in the stream).
  void Clear();
  // The limits in words, for logs and docs.
  std::string DescribeLimits() const;
  const NoiseProfile& profile() const { return profile_; }
  // The two-sided quantile the drift test uses (normal, or Student's t for a measured noise).
  double drift_z() const { return z_; }
  // Samples per value of a triad that holds its values (1: each sample its own), as of the last
  // full window.
  double samples_per_value(int triad) const {
    return samples_per_value_[static_cast<std::size_t>(triad)];
  }
  // The limit on |mean(second) - mean(first)| on one axis of a triad for halves of n1 and n2
  // samples: z sqrt(sigma^2 (1/n1 + 1/n2) + the bias wander's variance between them, scaled).
  // A triad that holds each value for `samples_per_value` samples (a magnetometer slower than
  // the stream) averages fewer values: its white part is that many times larger.
  double HalvesDriftLimit(int triad, int axis, double n1, double n2,
                          double samples_per_value = 1.0) const;
  // Scales a triad's bias wander (a sigma factor: the drift's strength the calibrator identified
  // from the session; 1 = options' bias_drift as given).
  void SetDriftScale(int triad, double scale);
  // Records what a calibrator identified in the profile and scales the allowance by it.
  void SetIdentifiedDrift(int triad, const IdentifiedDrift& identified);

 private:
  const Eigen::Vector3d& At(std::size_t logical, int triad) const;
  void Recompute();
  void Evaluate();
  void UpdateMedians();

  NoiseProfile profile_;
  StillnessOptions options_;
  int w_ = 0, h_ = 0;  // window and older-half sizes
  std::vector<StillSample> ring_;
  std::size_t head_ = 0, size_ = 0;
  std::int64_t pushes_since_recompute_ = 0, pushes_since_median_ = 0;
  bool medians_valid_ = false;
  std::array<bool, 3> use_{};
  // Per channel (3 triad x 3 axis): sums of (x - anchor), (x - anchor)^2 over the window and of
  // (x - anchor) over the older half.
  std::array<double, 9> anchor_{}, s1_{}, s2_{}, h1_{};
  std::array<double, 9> median_{}, robust_sigma_{};
  std::vector<double> scratch_;
  void UpdateHeld();

  double q_var_ = 0.0;
  double z_ = 0.0;  // two-sided quantile of the drift and rate tests
  // A triad that holds its values (a magnetometer slower than the stream): per ring slot, whether
  // each triad's value was fresh (bit 1 << t); the fresh count in the window; the samples per
  // value the limits were set for, and the variance test's limit at that many values.
  std::vector<std::uint8_t> fresh_;
  std::array<std::int64_t, 3> fresh_in_window_{};
  std::array<Eigen::Vector3d, 3> last_value_{};
  std::array<bool, 3> has_last_{};
  std::array<double, 3> samples_per_value_{1.0, 1.0, 1.0};
  std::array<double, 3> q_var_triad_{};
  // Per triad: its variance limit with every sample a value, and what its values' correlation
  // makes of a window's degrees of freedom and of its means' variance.
  std::array<double, 3> q_var_base_{};
  std::array<double, 3> dof_share_ = {1.0, 1.0, 1.0};
  std::array<double, 3> mean_inflation_ = {1.0, 1.0, 1.0};
  std::array<double, 3> drift_scale_{1.0, 1.0, 1.0};
  std::array<double, 9> window_drift_limit_{};  // HalvesDriftLimit for the window's halves
  std::int64_t still_run_ = 0;
  StillFinding finding_;
  double last_temp_c_ = std::numeric_limits<double>::quiet_NaN();  // the latest sample's
};

}  // namespace turncal
