#include <fmt/format.h>

#include <string>

#include "sim/capture.h"
#include "sim/session_sim.h"
#include "tools/sim_options.h"

#include "core/frames/mount.h"

namespace turncal::tools {

namespace {

// The session: the device, its models, the poses, the seed, the times and the output files.
void AddSessionOptions(CLI::App* cmd, SimCommandArgs* args) {
  cmd->add_option("--protocol", args->protocols,
                  "mip | gx2 | xbus | xbus-legacy (with --controller, one per --live, in order)")
      ->required();
  cmd->add_option("--model", args->models,
                  "accelerometer, magnetometer and/or gyroscope model (accel12|accel13, "
                  "mag13|mag22, gyro12|gyro21); default accel13 and mag13 and no gyro model (the "
                  "gyro then reads the table's rate plus a bias). With a gyro model the session "
                  "holds rate segments: the --poses file's (CSV phi,gamma,psi,AXIS,RATE) or the "
                  "default ones after the first static poses")
      ->capture_default_str();
  cmd->add_option("--poses", args->poses_file,
                  "pose plan: JSON or CSV of phi, gamma, psi in degrees (default: 26 cube "
                  "directions + 10 intermediate)");
  cmd->add_option("--seed", args->seed, "random seed (same seed: byte-identical output)")
      ->capture_default_str();
  cmd->add_option("--lever-arm", args->lever_arm_m,
                  "the IMU's offset from the table's centre, X Y Z in the table's inner frame, m "
                  "(default none): in motion the accelerometer sees its centripetal and "
                  "tangential acceleration")
      ->expected(3);
  cmd->add_option("--gyr-nonlinearity", args->gyr_nonlinearity_ppm_per_dps,
                  "with a gyro model: its scale grows with the rate by this many ppm per deg/s "
                  "(default 0: linear; the report's rate linearity shows it)");
  cmd->add_option("--dwell", args->dwell_s, "seconds at rest per pose after settling")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--rate", args->rate_hz,
                  "output rate in Hz (default: mip 500, gx2/xbus/xbus-legacy 100)");
  cmd->add_option("--baud", args->baud, "link baud rate (default: mip 921600, others 115200)");
  cmd->add_option("--class", args->sensor_class, "industrial | consumer (SENSORS.md)")
      ->check(CLI::IsMember({"industrial", "consumer"}))
      ->capture_default_str();
  cmd->add_option("--truth-out", args->truth_out, "JSON file of the true parameters");
  cmd->add_option("-o,--output", args->output, "the capture to write (.tcap)");
}

// The sensor's noise and drift, the table's motion and the injected faults.
void AddNoiseAndTableOptions(CLI::App* cmd, SimCommandArgs* args) {
  cmd->add_option("--acc-noise", args->acc_noise,
                  "accelerometer white noise density, m/s^2/sqrt(Hz) (default: the class's)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--acc-bias-instability", args->acc_bias_instability,
                  "accelerometer bias instability (Gauss-Markov 1 sigma), m/s^2")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--gyr-noise", args->gyr_noise, "gyro white noise density, rad/s/sqrt(Hz)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--mag-noise", args->mag_noise, "magnetometer white noise, Gauss RMS per sample")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--mag-bias-instability", args->mag_bias_instability,
                  "magnetometer bias instability (Gauss-Markov 1 sigma), Gauss")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--bias-tau", args->bias_tau_s,
                  "correlation time of the Gauss-Markov bias instability, s (default: the class's, "
                  "100)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--table-rate", args->table_rate_dps,
                  "move at this rate, deg/s, on every axis (a trapezoidal profile; the shorter way "
                  "round on the inner and outer axes); default: every move takes 3 s")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--table-accel", args->table_accel_dps2,
                  "the table's angular acceleration with --table-rate, deg/s^2")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--acc-random-walk", args->acc_random_walk,
                  "accelerometer bias random walk, m/s^2/sqrt(s) (default 0)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--mag-random-walk", args->mag_random_walk,
                  "magnetometer bias random walk, Gauss/sqrt(s) (default 0)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--acc-warmup", args->acc_warmup,
                  "accelerometer warm-up: 1 sigma per axis of the bias offset at power-on that "
                  "settles exponentially, m/s^2 (default 0)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--mag-warmup", args->mag_warmup,
                  "magnetometer warm-up offset at power-on, Gauss (default 0)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--gyr-warmup", args->gyr_warmup,
                  "gyroscope warm-up offset at power-on, rad/s (default 0; with a gyro model)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--warmup-tau", args->warmup_tau_s, "time constant of the warm-up, s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_flag("--no-quantisation", args->no_quantisation, "floats without ADC steps");
  cmd->add_option("--chamber", args->chamber,
                  "a climate chamber's profile: \"START; soak SETPOINT HOLD_S; ramp SETPOINT "
                  "DEGC_PER_MIN HOLD_S; ...\" (every sensor parameter then a quadratic in the "
                  "die's temperature, in the truth file; docs/THERMAL.md)")
      ->type_name("PROFILE");
  cmd->add_option("--die-tau", args->die_tau_s, "with --chamber: the die's lag behind the air, s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--self-heating", args->self_heating_c,
                  "with --chamber: the die's rise above the air after power-on, degC")
      ->capture_default_str();
  cmd->add_option("--temp-quantum", args->temp_quantum_c,
                  "with --chamber: the reported temperature's step, degC (0: none)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--temp-hysteresis", args->temp_hysteresis_c,
                  "with --chamber: the parameters lag the die's temperature by this play, degC "
                  "(rising: those of half of it below the die; falling: above; 0: none)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_flag("--repeat-poses", args->repeat_poses,
                "with --chamber: cycle the poses until the chamber's profile has run");
  cmd->add_option("--hand", args->hand_s,
                  "turn the device by hand for this many seconds instead of the poses: a "
                  "continuous smooth rotation, no pose announced (free mode's data; "
                  "docs/FREE.md \"In motion\")")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--hand-rate", args->hand_rate_dps, "with --hand: the RMS rate, deg/s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--hand-path", args->hand_path,
                  "with --hand: tumble (every direction), figure8, or planar (about the vertical "
                  "only, as a vehicle driven in a circle)")
      ->check(CLI::IsMember({"tumble", "figure8", "planar"}))
      ->capture_default_str();
  cmd->add_option("--hand-pauses", args->hand_pause_every_s,
                  "with --hand: stop and hold still after every this many seconds of motion "
                  "(0: never)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--hand-pause", args->hand_pause_s, "with --hand-pauses: each pause, s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--magnet", args->magnet_at_s,
                  "a magnet passes by this many seconds into the session: a field the sensor "
                  "does not own, rising and falling over --magnet-s to --magnet-peak (a bad "
                  "input free mode must name and leave out)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--magnet-s", args->magnet_s, "with --magnet: how long it is near, s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--magnet-peak", args->magnet_peak,
                  "with --magnet: its field at the closest, Gauss")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option(
         "--start", args->start_s,
         "seconds at rest before the first move (default 1, or with --live and --controller 3 s "
         "of wall time, 3 x --live-speed: the daemon's noise measurement sees fresh "
         "samples; 0: no still moment)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--mag-rate", args->mag_rate_hz,
                  "the magnetometer's own rate, Hz: below --rate the device repeats its last "
                  "value between updates (default: a new value in every sample)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--mag-lag", args->mag_lag_s,
                  "the magnetometer's lag behind the stream's clock, s (each sample carries the "
                  "field of this long before; default 0)")
      ->check(CLI::Range(0.0, 1.0));
  cmd->add_option("--mag-bandwidth", args->mag_bandwidth_hz,
                  "the magnetometer's bandwidth, Hz (a first-order low-pass; default none)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_flag("--mag-noise-filtered", args->mag_noise_filtered,
                "with --mag-bandwidth: the magnetometer's noise through the filter too (its "
                "values then correlate in time)");
  cmd->add_flag("--no-rate-segments", args->no_rate_segments,
                "with a gyro model: a table without a rate mode, static poses only (the gyro model "
                "then learns from the moves between them)");
  cmd->add_flag(
      "--faults", args->faults,
      fmt::format("inject faults: bit flips (~1 frame in 500), dropped bytes (~1 in 700), "
                  "one saturated sample, pose 1 announced {} s before the table finishes "
                  "its move ({} s before its dwell)",
                  sim::kSimEarlyBeforeMoveEnd_s,
                  SessionSimOptions{}.settle_s + sim::kSimEarlyBeforeMoveEnd_s));
}

// --live and --controller: the devices on ptys and the lab's controller on turncald's socket.
void AddLiveOptions(CLI::App* cmd, SimCommandArgs* args) {
  cmd->add_option("--live", args->lives,
                  "also stream the device's bytes to this pty at real time (pose events on "
                  "standard output); with --controller: a pty to create (or an existing tty) "
                  "per simulated device, the device answering the daemon's dialogue");
  cmd->add_option("--controller", args->controller,
                  "turncald's socket: play the lab's controller too -- announce every pose there "
                  "and hold the table until every device answered (docs/SIMULATOR.md)");
  cmd->add_option(
         "--answer-timeout", args->answer_timeout_s,
         "with --controller: wall-clock seconds the table waits for an answer before moving on "
         "(the daemon's timeouts are wall-clock too, whatever --live-speed)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--retries", args->retries,
                  "with --controller: a rejected pose is announced again this often, 0.25 s after "
                  "the rejection")
      ->check(CLI::Range(0, 100))
      ->capture_default_str();
  cmd->add_option("--bit-error-rate", args->bit_error_rate,
                  "with --controller: flip each bit the devices send with this probability "
                  "(line noise; e.g. 1e-4)")
      ->check(CLI::Range(0.0, 0.5));
  cmd->add_option("--unplug", args->unplugs,
                  "with --controller: POSE:mid|between[:DEVICE] -- the device's pty goes away "
                  "halfway through the pose's dwell, or when the table leaves the pose, and comes "
                  "back --unplug-s later (repeatable)");
  cmd->add_option("--unplug-s", args->unplug_s,
                  "with --controller: session seconds a device stays unplugged")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--device-state", args->device_state,
                  "with --live: a folder for the MIP devices' non-volatile storage "
                  "(DIR/SIM0001.nvm.json): a calibration the daemon saves into a device survives "
                  "its unplug and the next run");
  cmd->add_option("--lose-reply", args->lose_replies,
                  "with --controller: DESC:FUNCTION -- the first 3DM command (set 0x0C) with this "
                  "descriptor and function (1 write, 2 read, 3 save) is carried out but its reply "
                  "is lost, e.g. 0x3B:3 (repeatable)");
  cmd->add_option("--serial", args->serials,
                  "with --live: the devices' serial numbers, one per --live in order (an Xbus "
                  "device's is its device id, 8 hex digits); default SIM0001, ... and 03700001, "
                  "...");
  cmd->add_option("--mount", args->mounts,
                  "the unit's mount on the table (a fixture's slot): the case's axes along the "
                  "table's (\"-y+x+z\": case x along the table's -y ...) or X,Y,Z degrees; one "
                  "per --live device in order, the last for the rest (default +x+y+z; the truth "
                  "is about it: docs/BATCH.md)");
  cmd->add_option("--hold-end", args->hold_end_s,
                  "with --controller: after the last pose the table stays there this many session "
                  "seconds, the devices streaming (time to write a calibration into a device)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--live-speed", args->live_speed, "time scale of --live (2 = twice as fast)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
}

}  // namespace

void AddSimCommandOptions(CLI::App* cmd, SimCommandArgs* args) {
  AddSessionOptions(cmd, args);
  AddNoiseAndTableOptions(cmd, args);
  AddLiveOptions(cmd, args);
}

void ValidateSimArgs(SimCommandArgs* args) {
  if (args->output.empty() && args->lives.empty()) {
    throw CLI::ValidationError("sim", "give -o FILE.tcap and/or --live PATH");
  }
  args->protocol = args->protocols.front();
  args->live = args->lives.empty() ? std::string() : args->lives.front();
  if (args->serials.size() > args->lives.size()) {
    throw CLI::ValidationError("sim", "--serial: at most one per --live device");
  }
  for (std::size_t i = 0; i < args->serials.size(); ++i) {
    const auto& p = args->protocols.size() == 1 ? args->protocols.front() : args->protocols[i];
    const std::string& serial = args->serials[i];
    const bool hex8 = serial.size() == 8 &&
                      serial.find_first_not_of("0123456789abcdefABCDEF") == std::string::npos;
    if (serial.empty() || serial.size() > 16 || (p == "xbus" && !hex8)) {
      throw CLI::ValidationError(
          "sim", "--serial '" + serial +
                     "': 1 to 16 characters (an Xbus device's: its device id, 8 hex digits)");
    }
  }
  if (args->mounts.size() > std::max<std::size_t>(1, args->lives.size())) {
    throw CLI::ValidationError("sim", "--mount: at most one per --live device");
  }
  for (const auto& m : args->mounts) {
    Mat3<double> mount;
    if (std::string why; !ParseMountText(m, &mount, &why)) {
      throw CLI::ValidationError("sim", "--mount: " + why);
    }
  }
  if (!args->controller.empty()) {
    if (args->lives.empty()) throw CLI::ValidationError("sim", "--controller needs --live PTY");
    if (!args->output.empty() || args->faults) {
      throw CLI::ValidationError("sim", "--controller runs live only (no -o, no --faults)");
    }
    if (args->protocols.size() != 1 && args->protocols.size() != args->lives.size()) {
      throw CLI::ValidationError("sim", "give one --protocol, or one per --live");
    }
  } else if (args->bit_error_rate > 0 || !args->unplugs.empty() || !args->lose_replies.empty()) {
    throw CLI::ValidationError("sim",
                               "--bit-error-rate, --unplug and --lose-reply need --controller");
  } else if (args->lives.size() > 1 || args->protocols.size() > 1) {
    throw CLI::ValidationError("sim", "several --live devices need --controller");
  }
  if (args->hand_s > 0 && (!args->controller.empty() || !args->chamber.empty() ||
                           !args->poses_file.empty() || args->faults)) {
    throw CLI::ValidationError(
        "sim", "--hand turns the device by hand: no --controller, --chamber, --poses or --faults");
  }
}

}  // namespace turncal::tools
