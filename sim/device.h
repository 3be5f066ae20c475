#pragma once
// The device side of the configuration dialogues, for `turncal sim --live`: an emulated MIP or
// Xbus IMU that answers the host's commands (drivers/mip/mip_dialogue.h,
// drivers/xbus/xbus_dialogue.h) as the real device would, and says when it is streaming so the
// simulator sends sample frames only then.
//
// Feed it every byte the host wrote (any chunking); it returns the reply bytes to send back, in
// order. The host's bytes are scanned with the protocol's own decoder: a partial command waits for
// the rest (and is dropped after the protocol's timeout, by the emulator's clock), garbage and
// bad checksums are skipped and counted, and a command that is not understood gets the protocol's
// refusal (MIP NACK 1 "unknown command", Xbus Error 0x04 "invalid message").
//
// What each protocol answers (PROTOCOLS.md "Commands", "Configuration messages"):
//
// MIP (base set 0x01, 3DM set 0x0C; any other descriptor set: NACK 1; data sets >= 0x80 from the
// host are ignored and counted as unknown). One reply packet per command packet, with one ACK/NACK
// field (04 F1 cmd code) per command field, each followed by its reply data field.
//   0x01 ping, 0x02 set to idle (streaming stops), 0x06 resume (streaming restarts), 0x7E device
//   reset (back to the power-up state): ACK.
//   0x03 device info: ACK + 0x81 (u16 firmware, model name, model number, serial, lot, options;
//   16 characters each, space padded, longer strings truncated).
//   0x0C 0x06 IMU base rate: ACK + 0x83 (u16 Hz, MipBaseRate(rate_hz)).
//   0x0C 0x08 IMU message format: write (fn 1; descriptors 0x04-0x08, 0x0E, 0x12, 0x14, 0x18 with
//   decimation >= 1, else NACK 3), read (fn 2: ACK + 0x80 [n][desc, u16 decimation]...), save /
//   load / default (fn 3-5: ACK; default restores the power-up format).
//   0x0C 0x11 enable stream: write (fn 1, data set 0x80 or 0x82, else NACK 3), read (fn 2: ACK +
//   0x85 [set][on]), fn 3-5 ACK. Disabling set 0x80 also stops streaming().
//   0x0C 0x37 / 0x38 / 0x3A / 0x3B stored accel bias / gyro bias / hard-iron offset / soft-iron
//   matrix: when the identity has the value, read (fn 2: ACK + 0x9A / 0x9B / 0x9C / 0x9D, 3 or 9
//   big-endian f32), write (fn 1), save (fn 3: the values in use become the startup values, in
//   EmulatedIdentity::mip_nonvolatile_path when set; a file that cannot be written: NACK 4
//   "failed"), load (fn 4: the startup values back in use), default (fn 5: zeros, identity
//   matrix, in use); otherwise NACK 1 "unknown command", as a device without that setting does.
//   Power-up and device reset put the startup values in use. The device applies the values in
//   use to what it outputs (ApplyStored, sim/mip_storage.h). The default identity has a zero
//   accel and gyro bias and no hard- or soft-iron commands (so the dialogue records accel/gyro
//   bias 0 and no magnetometer correction).
//   Anything else (wrong function selector, short data): NACK 3 "bad parameter".
//
// Xbus (MTi 1/10/100 series, MTData2) and Xbus legacy (MTi/MTx, MTData): one reply message per
// request, answered in measurement and in config state alike.
//   GoToConfig 0x30 -> 0x31 (streaming stops); GoToMeasurement 0x10 -> 0x11 (streaming restarts);
//   WakeUpAck 0x3F from the host: config state, no reply; Reset 0x40 -> 0x41, back to measurement.
//   ReqDID 0x00 -> DeviceID 0x01 (u32); ReqProductCode 0x1C -> 0x1D (the product code);
//   ReqFWRev 0x12 -> 0x13 (major, minor, revision).
//   xbus only: SetOutputConfiguration 0xC0 with 1..32 (XDI, rate) pairs -> 0xC1 echoing them (what
//   was asked is applied); with no data it is the request, answered with the current
//   configuration; a length that is not a multiple of 4 or more than 32 pairs: Error 0x21.
//   xbus-legacy only: ReqOutputMode 0xD0 -> 0xD1 (u16) and ReqOutputSettings 0xD2 -> 0xD3 (u32)
//   from EmulatedIdentity::xbus_legacy_layout, which must be the layout the simulator streams;
//   setting them to that same value is acknowledged (empty 0xD1 / 0xD3), to anything else gets
//   Error 0x21 (the simulator cannot change what it streams).
//   Any other MID (including SetOutputConfiguration on a legacy device and ReqOutputMode on an
//   MTData2 device): Error 0x42 with code 0x04 "invalid message".
//
// gx2: no dialogue. streaming() is always true, nothing is answered, every byte is counted as
// ignored.
//
// Not thread-safe: one thread feeds the host's bytes and asks streaming().

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "core/sequencing/sample.h"
#include "drivers/device_spec.h"
#include "drivers/mip/mip_dialogue.h"
#include "drivers/xbus/xbus_decoder.h"

namespace turncal::sim {

// The legacy MTData layout the simulator streams for xbus-legacy: temperature, calibrated data
// (acc, gyr, mag as f32) and the sample counter, 42 data bytes. sim/capture.cc encodes its
// frames with a layout of the same value (kLegacyLayout, local to that file).
inline constexpr drivers::XbusLegacyLayout kSimXbusLegacyLayout{0x0003, 0x00000001};

// What the emulated device reports.
struct EmulatedIdentity {
  // MIP device information (16 characters each on the wire; longer strings are truncated).
  std::string model_name = "3DM-GX5-25 sim";
  std::string model_number = "6251-4220";
  std::string serial = "SIM0001";
  std::string lot = "sim";
  std::string options = "";
  std::uint16_t mip_firmware = 1234;
  // MIP stored calibration the device applies before output (0x37, 0x38, 0x3A, 0x3B and the
  // sensor-to-vehicle transform 0x33: a GX5-25 has all five, at their factory values); an absent
  // entry is a command the device does not know (NACK 1).
  drivers::mip::StoredCalibration mip_stored = {
      Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(),
      Eigen::Matrix3d::Identity(), Eigen::Matrix3d::Identity()};
  // The simulator's samples carry mip_stored (they are the device's output with those values in
  // use). The device's non-volatile storage: a JSON file that keeps what the host saved, read at
  // power-up, so a saved calibration survives the device's restart (a missing file: nothing
  // saved yet, mip_stored at power-up). Empty: saves last as long as the emulator.
  std::string mip_nonvolatile_path;

  // Xbus.
  std::uint32_t xbus_device_id = 0x03700001;
  std::string xbus_product_code = "MTi-3-sim";
  std::array<std::uint8_t, 3> xbus_firmware = {1, 0, 0};  // major, minor, revision
  // xbus-legacy: the MTData layout reported by ReqOutputMode / ReqOutputSettings.
  drivers::XbusLegacyLayout xbus_legacy_layout = kSimXbusLegacyLayout;
};

// The IMU base rate a MIP device streaming at `rate_hz` reports: the smallest whole multiple of
// rate_hz that is at least 1000 Hz (1000 for every rate dividing 1000: 100, 125, 200, 500, ...;
// 1200 for 300 Hz; rate_hz itself above 1000 Hz), rounded to whole Hz and clamped to [1, 65535];
// 1000 for a rate <= 0. The dialogue's decimation round(base / rate) then gives rate_hz back.
std::uint16_t MipBaseRate(double rate_hz);

class DeviceEmulator {
 public:
  // mip, xbus, xbus-legacy; gx2 has no dialogue: an emulator that streams always and answers
  // nothing, counting the bytes it ignored. `rate_hz`: the rate the simulator streams at.
  static std::unique_ptr<DeviceEmulator> Make(drivers::Protocol protocol,
                                              const EmulatedIdentity& id, double rate_hz);
  virtual ~DeviceEmulator();

  // Bytes the host wrote (any chunking: partial commands are buffered until complete; garbage and
  // bad checksums are skipped and counted). Returns the reply bytes to send back, in order.
  virtual std::vector<std::uint8_t> OnHostBytes(std::span<const std::uint8_t> bytes) = 0;

  // False while the device is idle (MIP: after Set-To-Idle until Resume, or while the host has
  // disabled the sensor stream 0x80) or in config state (Xbus: after GoToConfig until
  // GoToMeasurement): the simulator must not send sample frames then. True at power-up.
  virtual bool streaming() const = 0;

  struct Counters {
    std::uint64_t commands = 0;  // well-formed commands (MIP: command fields; Xbus: messages)
    std::uint64_t unknown_commands = 0;  // of those, refused as unknown (NACK 1 / Error 0x04)
    std::uint64_t bad_frames = 0;        // bad checksums, malformed frames, timed-out partials
    std::uint64_t ignored_bytes = 0;     // bytes outside well-formed commands (gx2: all)
  };
  virtual const Counters& counters() const = 0;

  virtual drivers::Protocol protocol() const = 0;

  // The simulator's sample as the device outputs it now, with the stored calibration in use
  // (MIP: what the host wrote, loaded or defaulted since power-up); unchanged otherwise.
  virtual void ApplyStored(Sample* s) const { (void)s; }
  // MIP: the stored calibration in use and the startup values; nullopt for other protocols.
  virtual std::optional<drivers::mip::StoredCalibration> mip_stored() const { return std::nullopt; }
  virtual std::optional<drivers::mip::StoredCalibration> mip_nonvolatile() const {
    return std::nullopt;
  }
  // The last failure of the non-volatile storage (unreadable at power-up, unwritable at a save);
  // empty when none.
  virtual const std::string& storage_error() const {
    static const std::string none;
    return none;
  }

  // The output rate the host's configuration asks for, from the accelerometer entry: MIP base
  // rate / decimation of 0x04 in the IMU message format written; Xbus the Acceleration (0x4020)
  // rate of SetOutputConfiguration (0xFFFF: the stream rate). nullopt until the host configured
  // one, and always for xbus-legacy and gx2. The simulator can compare it with what it streams.
  virtual std::optional<double> requested_rate_hz() const { return std::nullopt; }

  // The clock (monotonic nanoseconds) that times out partial commands; steady_clock by default.
  void set_clock(std::function<std::int64_t()> now_ns) { now_ns_ = std::move(now_ns); }

 protected:
  DeviceEmulator();
  std::int64_t NowNs() const { return now_ns_(); }

 private:
  std::function<std::int64_t()> now_ns_;
};

}  // namespace turncal::sim
