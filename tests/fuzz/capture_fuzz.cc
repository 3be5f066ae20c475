// libFuzzer target for the capture reader (drivers/capture/tcap.h, docs/capture-format.md) and
// what replays do with a capture (daemon::ReplayInto: the header's devices get decoders, 'D'
// records go to them, 'E' records are read as pose and dialogue events). The input is the whole
// capture file.
//
// Invariants checked on every input:
// - a refused header has a message; nothing escapes as an exception;
// - every byte after the header line is in a whole record or, when the capture is cut short,
//   among the trailing bytes; a corrupt record stops the records with a message;
// - what was read writes back (EncodeCaptureHeader, AppendCaptureRecord) to a capture that reads
//   as the same header and records;
// - ReplayInto hands the target only samples of the header's devices and announcements with
//   finite angles and a dwell in (0, 3600] s; every decoder's bytes add up.
//
// Run: tests/fuzz/run_fuzz.sh BUILD_DIR SECONDS capture
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <string>
#include <vector>

#include "daemon/station/capture_replay.h"
#include "drivers/capture/tcap.h"

namespace {

using turncal::drivers::CaptureHeader;
using turncal::drivers::CaptureReader;
using turncal::drivers::CaptureRecord;

bool SameHeader(const CaptureHeader& a, const CaptureHeader& b) {
  if (a.created != b.created || a.note != b.note || a.devices.size() != b.devices.size()) {
    return false;
  }
  for (std::size_t i = 0; i < a.devices.size(); ++i) {
    const auto& x = a.devices[i];
    const auto& y = b.devices[i];
    if (x.name != y.name || x.protocol != y.protocol || x.baud != y.baud ||
        x.output_mode != y.output_mode || x.output_settings != y.output_settings) {
      return false;
    }
  }
  return true;
}

class CheckingTarget : public turncal::daemon::ReplayTarget {
 public:
  explicit CheckingTarget(std::size_t devices) : devices_(devices) {}
  void OnSample(int device, const turncal::Sample& sample) override {
    if (device < 0 || static_cast<std::size_t>(device) >= devices_) __builtin_trap();
    if (sample.acc_mps2) sum_ += sample.acc_mps2->x();
  }
  bool OnAnnounce(const turncal::Announcement& a, const std::vector<int>& devices,
                  std::string* error) override {
    for (int i : devices) {
      if (i < 0 || static_cast<std::size_t>(i) >= devices_) __builtin_trap();
    }
    if (!std::isfinite(a.pose.phi_rad) || !std::isfinite(a.pose.gamma_rad) ||
        !std::isfinite(a.pose.psi_rad) || a.index < -1 ||
        (a.dwell_s && !(*a.dwell_s > 0 && *a.dwell_s <= 3600))) {
      __builtin_trap();
    }
    // Refuse every other one, as a sequencer in schedule mode would.
    if (++announced_ % 2 == 0) {
      *error = "refused";
      return false;
    }
    return true;
  }
  void OnTick(std::int64_t now_ns) override {
    if (now_ns < 0) __builtin_trap();
  }
  void OnFinish(std::int64_t now_ns) override {
    if (now_ns < 0 || finished_) __builtin_trap();
    finished_ = true;
  }
  bool finished_ = false;

 private:
  std::size_t devices_;
  std::uint64_t announced_ = 0;
  double sum_ = 0;
};

void Check(const std::uint8_t* data, std::size_t size) {
  const std::vector<std::uint8_t> bytes(data, data + size);
  CaptureReader reader;
  std::string error;
  if (!reader.Parse(bytes, &error)) {
    if (error.empty()) __builtin_trap();
    return;
  }
  // The header line: up to its '\n'.
  std::size_t at = 0;
  while (bytes[at] != '\n') ++at;
  ++at;
  std::vector<CaptureRecord> records;
  CaptureRecord r;
  std::size_t events = 0;
  while (reader.Next(&r)) {
    const auto type = static_cast<std::uint8_t>(r.type);
    if ((type != 'D' && type != 'T' && type != 'E') ||
        r.payload.size() > turncal::drivers::kCaptureMaxPayload) {
      __builtin_trap();
    }
    at += turncal::drivers::kCaptureRecordHeader + r.payload.size();
    // Replays skip records whose time is not plausible (beyond 2^62 ns).
    events += r.type == turncal::drivers::RecordType::kEvent && r.t_ns <= (std::uint64_t{1} << 62);
    records.push_back(r);
  }
  if (reader.Next(&r)) __builtin_trap();  // the end stays the end
  if (!reader.error().empty()) {
    if (reader.truncated() || at >= size) __builtin_trap();
  } else if (reader.truncated()) {
    if (reader.trailing_bytes() == 0 || at + reader.trailing_bytes() != size) __builtin_trap();
  } else if (at != size || reader.trailing_bytes() != 0) {
    __builtin_trap();
  }

  // Written back, it reads the same.
  const std::string line = turncal::drivers::EncodeCaptureHeader(reader.header());
  std::vector<std::uint8_t> copy(line.begin(), line.end());
  for (const auto& rec : records) {
    turncal::drivers::AppendCaptureRecord(rec.type, rec.device, rec.t_ns, rec.payload, &copy);
  }
  CaptureReader again;
  if (!again.Parse(copy, &error) || !SameHeader(reader.header(), again.header())) {
    __builtin_trap();
  }
  for (const auto& rec : records) {
    if (!again.Next(&r) || r.type != rec.type || r.device != rec.device || r.t_ns != rec.t_ns ||
        r.payload != rec.payload) {
      __builtin_trap();
    }
  }
  if (again.Next(&r) || again.truncated() || !again.error().empty()) __builtin_trap();

  // A replay of it.
  CaptureReader replayed;
  if (!replayed.Parse(bytes, &error)) __builtin_trap();
  const std::size_t devices = replayed.header().devices.size();
  CheckingTarget target(devices);
  turncal::daemon::ReplayStats stats;
  error.clear();
  if (!turncal::daemon::ReplayInto(&replayed, &target, true, {}, &stats, &error)) {
    if (error.empty()) __builtin_trap();
    return;
  }
  if (!target.finished_ || stats.decoders.size() != devices ||
      stats.pose_commands + stats.ignored_events + stats.dialogue_events != events) {
    __builtin_trap();
  }
  for (const auto& c : stats.decoders) {
    if (c.bytes_in != c.bytes_in_frames + c.bytes_skipped) __builtin_trap();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    Check(data, size);
  } catch (...) {
    __builtin_trap();  // nothing may escape: the readers of captures do not catch
  }
  return 0;
}
