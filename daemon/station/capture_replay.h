#pragma once
// A capture through the station's front half: each device's bytes through its decoder, the
// capture's pose events as announcements, in record order and at record times -- the same path
// live data takes (DESIGN.md "Pose sources": capture events go through the same code as
// announcements). ReplayInto feeds any ReplayTarget (the Station; one Sequencer per device for
// `turncal sequence`).

#include <algorithm>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/sequencing/sequencer.h"
#include "drivers/capture/tcap.h"
#include "drivers/decoder.h"

namespace turncal::daemon {

class ReplayTarget {
 public:
  virtual ~ReplayTarget() = default;
  virtual void OnSample(int device, const Sample& sample) = 0;
  // To the devices listed (indices in the capture's header; empty: every device). False with
  // *error when the announcement is refused (schedule mode, bad dwell).
  virtual bool OnAnnounce(const Announcement& announcement, const std::vector<int>& devices,
                          std::string* error) = 0;
  virtual void OnTick(std::int64_t now_ns) = 0;
  virtual void OnFinish(std::int64_t now_ns) = 0;
};

// Whether an announcement to `devices` (empty: every device) goes to device `i`.
inline bool AnnouncedTo(const std::vector<int>& devices, int i) {
  return devices.empty() || std::find(devices.begin(), devices.end(), i) != devices.end();
}

struct ReplayStats {
  std::vector<drivers::DecoderCounters> decoders;  // per device of the header
  std::uint64_t pose_commands = 0;                 // pose events in the capture
  std::uint64_t ignored_events = 0;                // not pose events (e.g. "end"), or not announced
  // {"event":"dialogue","state":"begin"|"end"} marks (turncald --record) and the received bytes
  // between them, which went to a configuration dialogue and are not decoded.
  std::uint64_t dialogue_events = 0;
  std::uint64_t dialogue_bytes = 0;
  std::vector<std::string> warnings;  // malformed events, bad device indices, truncation
};

// Replays the records `reader` has left into `target`. With `announce` false the pose events are
// counted as ignored (schedule mode). `sample_filter` (may be empty): a decoded sample for which
// it returns false never reaches the target (what-if replays, tests). False with *error when a
// device of the header cannot be decoded.
bool ReplayInto(drivers::CaptureReader* reader, ReplayTarget* target, bool announce,
                const std::function<bool(int device, const Sample&)>& sample_filter,
                ReplayStats* stats, std::string* error);

// The samples of device `device` (an index of the header) in the records `reader` has left, in
// time order, decoded as a replay decodes them (free mode's input: `turncal free`, the Monte
// Carlo of a hand's rotation); pose events counted in `stats`, not announced.
bool DecodeCaptureSamples(drivers::CaptureReader* reader, int device, std::vector<Sample>* out,
                          ReplayStats* stats, std::string* error);

struct ReplayOptions {
  SequencerOptions sequencer;
  // Schedule mode: poses in order, assigned to still segments; the capture's pose events are
  // then ignored (and counted). Absent: announced mode from the capture's pose events.
  std::optional<std::vector<TablePose>> schedule;
  PosePredictor predictor;  // per pose and triad; may be empty
  // What-if replays and tests: a decoded sample for which this returns false never reaches the
  // sequencer (as if lost on the way). Empty: every sample goes on.
  std::function<bool(int device, const Sample&)> sample_filter;
};

struct DeviceReplay {
  std::string name;
  drivers::DecoderCounters decoder;
  SampleCounts totals;  // the sequencer's: used, flagged, outliers, lost
  std::vector<SequencerEvent> events;
  std::vector<PoseRecord> records;  // captured, in order
  std::optional<NoiseProfile> noise;
};

struct ReplayResult {
  std::vector<DeviceReplay> devices;
  std::uint64_t pose_commands = 0;
  std::uint64_t ignored_events = 0;
  std::vector<std::string> warnings;
};

// One Sequencer per device of the capture. `on_event` (optional) sees every sequencer event as
// it happens, with the device's index. False with *error for options that cannot work.
bool ReplayCapture(drivers::CaptureReader* reader, const ReplayOptions& options,
                   ReplayResult* result, std::string* error,
                   const std::function<void(int, const SequencerEvent&)>& on_event = {});

}  // namespace turncal::daemon
