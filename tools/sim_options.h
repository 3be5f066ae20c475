#pragma once
// `turncal sim`'s command line (tools/sim_command.cc): what it parses into, its options and the
// checks of the options that go together.

#include <CLI/CLI.hpp>
#include <cstdint>
#include <string>
#include <vector>

#include "core/planning/table_motion.h"
#include "sim/chamber.h"

namespace turncal::tools {

struct SimCommandArgs {
  std::vector<std::string> protocols;
  std::string protocol;  // the first of protocols
  std::vector<std::string> models = {"accel13", "mag13"};
  std::string poses_file;
  std::uint64_t seed = 1;
  double dwell_s = 5.0;
  std::vector<double> lever_arm_m;  // x, y, z in the table's inner frame
  double gyr_nonlinearity_ppm_per_dps = 0.0;
  double rate_hz = 0.0;  // 0: the protocol's default
  int baud = 0;          // 0: the protocol's default
  std::string sensor_class = "industrial";
  std::string truth_out;
  std::string output;
  double burst_ms = 16.0;
  bool faults = false;
  // Overrides of the class's noise (negative: the class's value).
  double acc_noise = -1, acc_bias_instability = -1, gyr_noise = -1, mag_noise = -1,
         mag_bias_instability = -1;
  double bias_tau_s = -1, acc_random_walk = 0, mag_random_walk = 0, acc_warmup = 0, mag_warmup = 0,
         gyr_warmup = 0, warmup_tau_s = 60;
  bool no_quantisation = false;
  bool no_rate_segments = false;  // a table without a rate mode
  double table_rate_dps = 0;      // 0: every move takes 3 s (SessionSimOptions::move_s)
  double table_accel_dps2 = TableMotion{}.accel_dps2[0];
  std::vector<std::string> lives;  // ptys (or writable ttys/files) to stream to at real time
  std::string live;                // the first of lives
  double live_speed = 1.0;
  double hold_end_s = 0;
  std::vector<std::string> lose_replies;  // DESC:FUNCTION
  std::vector<std::string> serials;       // --serial, one per --live device
  std::vector<std::string> mounts;        // --mount, one per device (the last for the rest)
  std::string controller;                 // turncald's socket: play the controller (sim/live.h)
  double answer_timeout_s = 120;
  int retries = 2;
  double bit_error_rate = 0;
  std::vector<std::string> unplugs;  // POSE:mid|between[:DEVICE]
  double unplug_s = 2.0;
  std::string device_state;
  // A climate chamber (issue 36; docs/THERMAL.md): its profile ("25; ramp -20 2 1200; soak 70
  // 600"), the die's lag, self-heating and reported step, and the poses cycled until it has run.
  std::string chamber;
  double die_tau_s = DieThermal{}.tau_s;
  double self_heating_c = DieThermal{}.self_heating_c;
  double temp_quantum_c = DieThermal{}.quantum_c;
  double temp_hysteresis_c = DieThermal{}.hysteresis_c;
  bool repeat_poses = false;
  // A hand's continuous rotation instead of the poses (issue 37; sim/hand_motion.h): its length
  // (0: none), RMS rate, path, pauses; the rest before it; the magnetometer's own rate and
  // bandwidth (0: every sample, no filter).
  double hand_s = 0;
  double hand_rate_dps = 90;
  std::string hand_path = "tumble";
  double hand_pause_every_s = 0;
  double hand_pause_s = 1.0;
  // A magnet passing by at magnet_at_s for magnet_s, its field's peak magnet_peak (Gauss).
  double magnet_at_s = -1.0, magnet_s = 1.0, magnet_peak = 0.1;
  double start_s = -1;  // negative: SessionSimOptions' (1 s)
  double mag_rate_hz = 0;
  double mag_bandwidth_hz = 0;
  double mag_lag_s = 0;
  bool mag_noise_filtered = false;
};

// Registers `turncal sim`'s options on `cmd`, filling `args`, in the order --help lists them.
void AddSimCommandOptions(CLI::App* cmd, SimCommandArgs* args);

// The checks of the options that go together (CLI::ValidationError with the message); sets
// `protocol` and `live` to the first of their lists.
void ValidateSimArgs(SimCommandArgs* args);

}  // namespace turncal::tools
