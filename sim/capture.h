#pragma once
// The capture `turncal sim` writes, built in memory: the simulated session (sim/session_sim.h)
// turned into .tcap records (the device's start-up traffic, the encoded sample frames in bursts,
// the controller's pose events, an "end" event), with faults injected on request. `turncal sim`
// writes exactly these records; tests build the same capture in-process from the same options.
//
// Pose events are JSON 'E' records
//   {"event":"pose","index":i,"phi_deg":…,"gamma_deg":…,"psi_deg":…,"hold_s":…}
// where hold_s is how long the table holds the pose after the announcement (the dwell, plus the
// early amount for an announcement made early); a rate segment's is
//   {"event":"rate","index":i,"rate_axis":…,"rate_dps":…,"phi_deg":…,…,"dwell_s":…,"hold_s":…}
// with dwell_s the session's dwell (the sequencer collects whole revolutions of at least that).
// Pure computation: the same options give the same bytes.

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "drivers/capture/tcap.h"
#include "drivers/device_spec.h"
#include "sim/session_sim.h"

namespace turncal::sim {

// --faults: the early pose announcement comes this long before the table finishes its move into
// the pose (so settle_s + this before the dwell starts), while the table is still visibly moving.
inline constexpr double kSimEarlyBeforeMoveEnd_s = 0.5;

// The sample rate the simulator gives a protocol when none is asked for (mip 500 Hz, others 100).
double SimDefaultRateHz(drivers::Protocol protocol);

struct SimCaptureOptions {
  drivers::Protocol protocol = drivers::Protocol::kMip;
  std::string accel_model = "accel13";  // an accelerometer model (MakeModel)
  std::string mag_model = "mag13";      // a magnetometer model; not mag-physical
  // A gyroscope model (gyro12, gyro21) whose truth the gyro follows; empty: the gyro is the
  // table's rate plus a turn-on bias (SimulateSession). Rate segments among the poses need one.
  std::string gyro_model;
  std::vector<TablePose> poses = DefaultSessionPoses();
  // The unit's nominal mount on the table (issue 38; core/frames/mount.h): its models' context,
  // so that its truth's mounting angles are small about it. Identity: case along the table.
  Mat3<double> mount = Mat3<double>::Identity();
  // Noise class, dwell, seed, ... session.rate_hz <= 0 (the default here): the protocol's
  // default, mip 500 Hz, gx2 / xbus / xbus-legacy 100 Hz.
  SessionSimOptions session = [] {
    SessionSimOptions o;
    o.rate_hz = 0.0;
    return o;
  }();
  int baud = 0;  // <= 0: the protocol's default, mip 921600, others 115200
  // Bit flips (~1 frame in 500), dropped bytes (~1 in 700), one saturated sample, and pose 1
  // announced kSimEarlyBeforeMoveEnd_s before the table finishes its move.
  bool faults = false;
  double burst_ms = 16.0;  // the device's bytes go into one received record per this much time
};

// What --faults injected (all zero, early_pose_index -1, without faults).
struct SimFaultReport {
  int bit_flips = 0;
  int dropped_bytes = 0;
  std::size_t saturated_index = 0;  // index into SimulatedSession::samples
  int early_pose_index = -1;        // the pose announced early; -1 if none
  double early_s = 0.0;             // how much before the start of its dwell
};

struct SimCapture {
  drivers::CaptureHeader header;
  std::vector<drivers::CaptureRecord> records;
  SimulatedSession session;           // the samples (before faults), events and truths
  SessionSimOptions session_options;  // as simulated (rate_hz resolved)
  int baud = 0;                       // as resolved
  // Capture time of session time 0: a sample's record time base is offset_ns + t_host_ns, and an
  // event at session time t_s is at offset_ns + llround(t_s * 1e9) (minus early_s if early).
  std::int64_t offset_ns = 0;
  std::string accel_model;
  std::string mag_model;
  std::string gyro_model;                         // empty: none
  Mat3<double> mount = Mat3<double>::Identity();  // as simulated (the truth is about it)
  SimFaultReport faults;
};

// One sample as the simulated device frames it (mip: sensor packet without counter; gx2: 0xCB
// reply; xbus: MTData2; xbus-legacy: MTData in the simulator's layout).
std::vector<std::uint8_t> EncodeSimSample(drivers::Protocol protocol, const Sample& sample);

// Simulates the session and builds its capture. False with a message (no "turncal sim:" prefix)
// for an unknown or wrong-kind model, invalid session options, or a sample rate the link's baud
// cannot carry.
bool BuildSimCapture(const SimCaptureOptions& options, SimCapture* out, std::string* error);

// Writes the capture's records to a .tcap file at `path` (what `turncal sim -o` writes). False
// with a message when the file cannot be written.
bool WriteSimCapture(const SimCapture& capture, const std::string& path, std::string* error);

// The capture's .tcap bytes (header and records), as WriteSimCapture writes them, in memory.
std::vector<std::uint8_t> EncodeSimCapture(const SimCapture& capture);

}  // namespace turncal::sim
