#include "daemon/station/capture_replay.h"

#include <fmt/format.h>

#include <algorithm>
#include <memory>
#include <nlohmann/json.hpp>

#include "drivers/decoder_factory.h"
#include "protocol/sequencer_json.h"

namespace turncal::daemon {
namespace {

class TargetSink : public drivers::DecoderSink {
 public:
  TargetSink(ReplayTarget* target, int device,
             const std::function<bool(int, const Sample&)>* filter)
      : target_(target), device_(device), filter_(filter) {}
  void OnFrame(const drivers::FrameView&) override {}
  void OnSample(const Sample& sample) override {
    if (*filter_ && !(*filter_)(device_, sample)) return;
    target_->OnSample(device_, sample);
  }

 private:
  ReplayTarget* target_;
  int device_;
  const std::function<bool(int, const Sample&)>* filter_;
};

// One sequencer per device.
class SequencerTarget : public ReplayTarget {
 public:
  explicit SequencerTarget(std::vector<std::unique_ptr<Sequencer>> sequencers)
      : sequencers_(std::move(sequencers)) {}
  void OnSample(int device, const Sample& sample) override {
    sequencers_[static_cast<std::size_t>(device)]->Push(sample);
  }
  bool OnAnnounce(const Announcement& a, const std::vector<int>& devices,
                  std::string* error) override {
    bool ok = true;
    for (std::size_t i = 0; i < sequencers_.size(); ++i) {
      if (AnnouncedTo(devices, static_cast<int>(i))) ok = sequencers_[i]->Announce(a, error) && ok;
    }
    return ok;
  }
  void OnTick(std::int64_t now_ns) override {
    for (auto& s : sequencers_) s->Tick(now_ns);
  }
  void OnFinish(std::int64_t now_ns) override {
    for (auto& s : sequencers_) s->Finish(now_ns);
  }
  const Sequencer& sequencer(std::size_t i) const { return *sequencers_[i]; }

 private:
  std::vector<std::unique_ptr<Sequencer>> sequencers_;
};

}  // namespace

bool ReplayInto(drivers::CaptureReader* reader, ReplayTarget* target, bool announce,
                const std::function<bool(int device, const Sample&)>& sample_filter,
                ReplayStats* stats, std::string* error) {
  const auto& devices = reader->header().devices;
  if (devices.empty()) {
    if (error) *error = "the capture's header names no device";
    return false;
  }
  *stats = ReplayStats{};
  std::vector<std::unique_ptr<TargetSink>> sinks;
  std::vector<std::unique_ptr<drivers::Decoder>> decoders;
  for (std::size_t i = 0; i < devices.size(); ++i) {
    drivers::DecoderOptions d;
    d.device = devices[i].name;
    if (devices[i].output_mode) d.xbus_legacy.output_mode = *devices[i].output_mode;
    if (devices[i].output_settings) d.xbus_legacy.output_settings = *devices[i].output_settings;
    sinks.push_back(std::make_unique<TargetSink>(target, static_cast<int>(i), &sample_filter));
    std::string why;
    decoders.push_back(drivers::MakeDecoder(devices[i].protocol, d, sinks.back().get(), &why));
    if (!decoders.back()) {
      if (error) *error = fmt::format("device '{}': {}", devices[i].name, why);
      return false;
    }
  }
  drivers::CaptureRecord r;
  std::int64_t last_ns = 0;
  // A device's configuration dialogue, as turncald --record marks it: its bytes went to the
  // dialogue, not to the decoder, and are skipped here too (the same samples as live).
  std::vector<bool> in_dialogue(decoders.size(), false);
  while (reader->Next(&r)) {
    // Host times are nanoseconds since the capture began; beyond 2^62 (146 years) a record is
    // corrupt, and the arithmetic on it would overflow.
    if (r.t_ns > (std::uint64_t{1} << 62)) {
      stats->warnings.push_back(
          fmt::format("a record's time {} ns is not plausible; skipped", r.t_ns));
      continue;
    }
    const auto t_ns = static_cast<std::int64_t>(r.t_ns);
    last_ns = std::max(last_ns, t_ns);
    if (r.type == drivers::RecordType::kEvent) {
      const auto j = nlohmann::json::parse(r.payload.begin(), r.payload.end(), nullptr, false);
      // A key's text; "" when absent or not a string (json::value() would throw).
      const auto text = [&j](const char* key) {
        const auto it = j.find(key);
        return it != j.end() && it->is_string() ? it->get<std::string>() : std::string();
      };
      if (j.is_object() && text("event") == "dialogue" && r.device < decoders.size()) {
        in_dialogue[r.device] = text("state") == "begin";
        // Live, a device being (re)configured has no decoder: what the old one held is finished.
        if (in_dialogue[r.device]) decoders[r.device]->Finish();
        ++stats->dialogue_events;
        continue;
      }
      Announcement a;
      bool is_pose = false;
      std::string why;
      const bool ok = protocol::ParsePoseCommand(j, t_ns, &a, &is_pose, &why);
      if (!is_pose) {
        ++stats->ignored_events;
        continue;
      }
      ++stats->pose_commands;
      // turncald --record lists the devices a pose went to (a retry goes to one); a capture
      // without the list announces it to every device.
      std::vector<int> to;
      bool listed_ok = true;
      if (const auto listed = j.find("devices"); ok && listed != j.end()) {
        listed_ok = listed->is_array();
        for (const auto& name : listed_ok ? *listed : nlohmann::json::array()) {
          const auto& header = reader->header().devices;
          const auto it = std::find_if(header.begin(), header.end(), [&](const auto& h) {
            return name.is_string() && h.name == name.get<std::string>();
          });
          if (it == header.end()) {
            listed_ok = false;
            break;
          }
          to.push_back(static_cast<int>(it - header.begin()));
        }
        if (!listed_ok) why = "pose: 'devices' must list device names of the capture's header";
      }
      if (!ok || !listed_ok) {
        stats->warnings.push_back(fmt::format("event at {:.3f} s: {}", t_ns * 1e-9, why));
      } else if (!announce) {
        ++stats->ignored_events;
      } else if (!target->OnAnnounce(a, to, &why)) {
        stats->warnings.push_back(fmt::format("event at {:.3f} s: {}", t_ns * 1e-9, why));
      }
      continue;
    }
    if (r.device >= decoders.size()) {
      stats->warnings.push_back(
          fmt::format("a record names device {} of {}; skipped", r.device, decoders.size()));
      continue;
    }
    target->OnTick(t_ns);
    if (r.type == drivers::RecordType::kReceived) {
      if (in_dialogue[r.device]) {
        stats->dialogue_bytes += r.payload.size();
      } else {
        decoders[r.device]->Push(r.payload, t_ns);
      }
    }
  }
  if (!reader->error().empty()) stats->warnings.push_back(reader->error());
  if (reader->truncated()) {
    stats->warnings.push_back(fmt::format("the capture ends inside a record ({} bytes ignored)",
                                          reader->trailing_bytes()));
  }
  for (auto& d : decoders) {
    d->Finish();
    stats->decoders.push_back(d->counters());
  }
  target->OnFinish(last_ns);
  return true;
}

bool ReplayCapture(drivers::CaptureReader* reader, const ReplayOptions& options,
                   ReplayResult* result, std::string* error,
                   const std::function<void(int, const SequencerEvent&)>& on_event) {
  if (!options.sequencer.IsValid(error)) return false;
  const auto& devices = reader->header().devices;
  *result = ReplayResult{};
  result->devices.resize(devices.size());
  std::vector<std::unique_ptr<Sequencer>> sequencers;
  for (std::size_t i = 0; i < devices.size(); ++i) {
    DeviceReplay* out = &result->devices[i];
    out->name = devices[i].name;
    const int device_index = static_cast<int>(i);
    sequencers.push_back(std::make_unique<Sequencer>(
        options.sequencer, [out, device_index, &on_event](const SequencerEvent& e) {
          out->events.push_back(e);
          if (e.kind == SequencerEventKind::kCaptured && e.record)
            out->records.push_back(*e.record);
          if (on_event) on_event(device_index, e);
        }));
    if (options.predictor) sequencers.back()->SetPredictor(options.predictor);
    if (options.schedule && !sequencers.back()->SetSchedule(*options.schedule, error)) return false;
  }
  SequencerTarget target(std::move(sequencers));
  ReplayStats stats;
  if (!ReplayInto(reader, &target, !options.schedule, options.sample_filter, &stats, error)) {
    return false;
  }
  result->pose_commands = stats.pose_commands;
  result->ignored_events = stats.ignored_events;
  result->warnings = stats.warnings;
  for (std::size_t i = 0; i < devices.size(); ++i) {
    result->devices[i].decoder = stats.decoders[i];
    result->devices[i].totals = target.sequencer(i).totals();
    if (target.sequencer(i).noise()) result->devices[i].noise = *target.sequencer(i).noise();
  }
  return true;
}

namespace {

class SampleSink : public ReplayTarget {
 public:
  SampleSink(int device, std::vector<Sample>* out) : device_(device), out_(out) {}
  void OnSample(int device, const Sample& s) override {
    if (device == device_) out_->push_back(s);
  }
  bool OnAnnounce(const Announcement&, const std::vector<int>&, std::string*) override {
    return true;
  }
  void OnTick(std::int64_t) override {}
  void OnFinish(std::int64_t) override {}

 private:
  int device_;
  std::vector<Sample>* out_;
};

}  // namespace

bool DecodeCaptureSamples(drivers::CaptureReader* reader, int device, std::vector<Sample>* out,
                          ReplayStats* stats, std::string* error) {
  SampleSink sink(device, out);
  return ReplayInto(reader, &sink, false, {}, stats, error);
}

}  // namespace turncal::daemon
