#pragma once
// A climate chamber and the sensor's die in it (issue 36; SENSORS.md "Temperature"): the profile
// the chamber's air follows, and the die temperature the sensor reports.
//
// The profile starts at `start_c` and runs its steps in order: each moves the set-point to
// `setpoint_c` at `rate_c_per_min` (0: at once, as far as the chamber is concerned) and then
// holds it for `hold_s`. The air follows the set-point exactly (a chamber's own lag is small
// against the die's). The die lags the air by a first-order time constant `tau_s` and sits above
// it by self-heating that grows after power-on (time 0) as self_heating_c (1 - exp(-t /
// self_heating_tau_s)). The temperature the device reports is the die's, rounded to `quantum_c`
// (0: a float, as MIP and Xbus send; some consumer parts report 1 degree C steps).
//
// Hysteresis (`hysteresis_c`, 0: none): the parameters follow not the die's temperature but a
// "play" of it (the elementary hysteresis operator): a temperature that stays within
// hysteresis_c / 2 of the die and moves only when the die pushes it, so that after a rise the
// parameters are those of hysteresis_c / 2 below the die, after a fall above it, and at a
// turning point they stand still until the die has moved hysteresis_c. A calibration over
// temperature (a single p(T)) cannot follow it; the truth holds that temperature per pose.

#include <string>
#include <vector>

namespace turncal {

struct ChamberStep {
  double setpoint_c = 25.0;
  double rate_c_per_min = 0.0;  // 0: a step
  double hold_s = 0.0;
};

struct ChamberProfile {
  double start_c = 25.0;
  std::vector<ChamberStep> steps;

  // The set-point (the air's temperature) at session time t_s; before 0 and after the last
  // step, the start and the last set-point.
  double AirAt(double t_s) const;
  // Seconds from 0 to the end of the last hold.
  double duration_s() const;
  // The middle of the temperatures it visits (the start and every set-point).
  double middle_c() const;
  bool IsValid(std::string* error) const;
  // "START; soak T HOLD_S; ramp T RATE_C_PER_MIN [HOLD_S]; ...", e.g. "25; ramp -20 2 1200;
  // ramp 70 2 1200; ramp 25 2" (the simulator's --chamber). False with the reason.
  static bool Parse(const std::string& text, ChamberProfile* out, std::string* error);
  // The same text back.
  std::string ToString() const;
  // Classic soaks: from `start_c`, a step to each plateau at `rate_c_per_min` and a hold of
  // `hold_s` there.
  static ChamberProfile Soaks(double start_c, const std::vector<double>& plateaus_c,
                              double rate_c_per_min, double hold_s);
};

struct DieThermal {
  double tau_s = 300.0;  // the die's lag behind the air
  double self_heating_c = 3.0;
  double self_heating_tau_s = 600.0;
  double quantum_c = 0.0;     // the reported temperature's step (0: none)
  double hysteresis_c = 0.0;  // the play between the die and the parameters' temperature

  bool IsValid(std::string* error) const;
};

// The die's temperature through a session, advanced sample by sample (exact for an air
// temperature constant over each step; the samples are milliseconds apart, the lag minutes).
class DieTemperature {
 public:
  DieTemperature(const ChamberProfile& chamber, const DieThermal& die);
  // The die's temperature at t_s (>= the previous call's t_s).
  double Advance(double t_s);
  // What the device reports for a die temperature.
  double Reported(double die_c) const;
  // The temperature the parameters are at (the die's, through the hysteresis's play).
  double parameter_c() const { return parameter_c_; }

 private:
  const ChamberProfile& chamber_;
  DieThermal die_;
  double t_s_ = 0.0;
  double die_c_ = 0.0;
  double parameter_c_ = 0.0;
};

}  // namespace turncal
