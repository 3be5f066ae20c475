#pragma once
// The publish gate (MODELS.md "What the publish gate protects"): a calibration is published only
// when the data determine every parameter the live correction depends on, each of those
// parameters is known to its tolerance, chi^2 agrees with the noise, and no pose is extreme.
// Installation parameters (beta, dB, and eps when the output is in the case frame) are reported
// with their sigma, never gated. The gate returns every reason it fails, not only the first.

#include <map>
#include <string>
#include <vector>

#include "core/analysis/observability.h"
#include "core/estimation/calibrator.h"

namespace turncal {

// Tolerances on 1 sigma, by the kind of quantity.
struct GateTolerances {
  double scale_factor = 100e-6;               // S: 100 ppm
  double angle_rad = 0.01 * M_PI / 180;       // alpha (and eps in the table frame): 0.01 deg
  double acceleration_mps2 = 1e-3 * 9.80665;  // accelerometer bias: 1 mg
  double gain = 1e-3;                         // magnetometer G entries (and K): 0.1 %
  double field = 1e-3;                        // magnetometer bias: 1 mG (device unit: Gauss)
  double angular_rate_radps = 10.0 * M_PI / 180 / 3600;  // gyroscope bias: 10 deg/h
  // gyroscope g-sensitivity: 10 deg/h/g, rad/s per m/s^2
  double g_sensitivity = 10.0 * M_PI / 180 / 3600 / 9.80665;
  // accelerometer second-order K2: 100 ug/g^2, per m/s^2
  double second_order = 100e-6 / 9.80665;
};

// Defaults for a sensor class of SENSORS.md: "industrial" (tactical-grade targets: 100 ppm,
// 0.01 deg, 1 mg; gain 1e-3, 1 mG; gyro bias 10 deg/h, g-sensitivity 10 deg/h/g; K2 100 ug/g^2)
// or "consumer" (1000 ppm, 0.1 deg, 2 mg; gain 2e-3, 2 mG; 100 deg/h, 200 deg/h/g; 1000 ug/g^2).
// False when the name is unknown.
bool GateTolerancesForClass(const std::string& sensor_class, GateTolerances* out);

struct GateOptions {
  GateTolerances tolerances;
  // Per-parameter tolerances by name (MODELS.md's names); they override the kind's tolerance.
  std::map<std::string, double> parameter_tolerance;
  // chi^2 must not be improbably large for the noise model: p-value at least this.
  double min_p_value = 1e-3;
  // ... and there must be something to test: at least this many redundant equations.
  int min_dof = 3;
  // No pose may have a normalised residual sqrt(r^T r / 3) above this (chi^2 with 3 dof above
  // 75: probability 5e-16 for a clean pose).
  double max_normalized_residual = 5.0;
  // mag22's live correction uses G, which moves along the model's second gauge direction: by
  // default the gate refuses it (use mag13); set this to publish in the documented gauge anyway.
  bool accept_gauge_dependent_correction = false;

  bool IsValid(std::string* error) const;
};

// The class's whole default gate: its tolerances (above) and the redundancy its chi^2 test needs,
// min_dof: 3 for industrial sensors, 6 for consumer ones. With 5 redundant equations (accel13 at
// 6 poses) a consumer-grade accelerometer's first calibration under the drift model had bias
// estimates off by 0.2-0.25 sigma on average and, on other pose sequences, sigma up to 30 % small;
// with 6 or more every parameter was honest (docs/OBSERVABILITY.md "Honest at the first gate").
// Other fields are left as they are.
bool GateDefaultsForClass(const std::string& sensor_class, GateOptions* out);

// Indices of the parameters the live correction depends on: sensor parameters, and mounting
// angles when the correction is output in the table frame.
std::vector<int> GatedParameters(const MeasurementModel& model);

// The 1 sigma a gated parameter must reach.
double ToleranceFor(const ParameterInfo& parameter, const GateOptions& options);

// The 1 sigma a free model's parameter (core/modeling/free_model.h, a calibration without poses)
// must reach, or a negative number for one never gated (the rotation between two triads, the
// dip: they do not enter the triad's own correction). A triad's gains k (about 1: imu_tk's scale)
// are judged as scale factors, by the scale-factor tolerance, and `judged_as` (when given)
// receives the parameter as judged, for FormatSigma; the rest by their unit, and per-parameter
// tolerances by name override both.
double FreeToleranceFor(const ParameterInfo& parameter, const GateOptions& options,
                        ParameterInfo* judged_as = nullptr);

struct GateResult {
  bool pass = false;
  std::vector<std::string> reasons;  // every failed check, in plain words
  std::vector<std::string> missing;  // gated parameters the poses do not determine
  std::vector<std::string> notes;    // installation parameters and caveats; never a failure
};

// The gate's fit part, shared by the isothermal and the thermal gate: chi^2 consistent with the
// noise (enough redundancy, p at least min_p_value, else a note when the fit check is not ok) and
// no pose with an extreme normalised residual; reasons and notes appended to `result`. `cause`
// names what a rejected chi^2 likely means when the fit check has no cause of its own.
void AddFitReasons(double chi2, int dof, double p_value, const FitCheck& fit,
                   const std::vector<PoseResidual>& residuals, SensorKind sensor,
                   const GateOptions& options, const std::string& cause, GateResult* result);

// The gate on an estimate and the data analysis at that estimate over the same poses.
GateResult EvaluateGate(const MeasurementModel& model, const Estimate& estimate,
                        const DataReport& data, const GateOptions& options);

// The precision part alone (also on predicted sigmas, for pose planning): one reason per gated
// parameter whose sigma exceeds its tolerance; parameters with `skip[j]` set are left out.
std::vector<std::string> PrecisionShortfalls(const MeasurementModel& model,
                                             const Eigen::VectorXd& sigma,
                                             const GateOptions& options,
                                             const std::vector<bool>* skip = nullptr);

}  // namespace turncal
