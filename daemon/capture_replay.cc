#include "daemon/capture_replay.h"

#include <fmt/format.h>

#include <memory>
#include <nlohmann/json.hpp>

#include "drivers/decoder_factory.h"
#include "protocol/sequencer_json.h"

namespace turncal::daemon {
namespace {

class SequencerSink : public drivers::DecoderSink {
 public:
  SequencerSink(Sequencer* sequencer, int device,
                const std::function<bool(int, const Sample&)>* filter)
      : sequencer_(sequencer), device_(device), filter_(filter) {}
  void OnFrame(const drivers::FrameView&) override {}
  void OnSample(const Sample& sample) override {
    if (*filter_ && !(*filter_)(device_, sample)) return;
    sequencer_->Push(sample);
  }

 private:
  Sequencer* sequencer_;
  int device_;
  const std::function<bool(int, const Sample&)>* filter_;
};

}  // namespace

bool ReplayCapture(drivers::CaptureReader* reader, const ReplayOptions& options,
                   ReplayResult* result, std::string* error,
                   const std::function<void(int, const SequencerEvent&)>& on_event) {
  if (!options.sequencer.IsValid(error)) return false;
  const auto& devices = reader->header().devices;
  if (devices.empty()) {
    if (error) *error = "the capture's header names no device";
    return false;
  }
  *result = ReplayResult{};
  result->devices.resize(devices.size());
  std::vector<std::unique_ptr<Sequencer>> sequencers;
  std::vector<std::unique_ptr<SequencerSink>> sinks;
  std::vector<std::unique_ptr<drivers::Decoder>> decoders;
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
    drivers::DecoderOptions d;
    d.device = devices[i].name;
    if (devices[i].output_mode) d.xbus_legacy.output_mode = *devices[i].output_mode;
    if (devices[i].output_settings) d.xbus_legacy.output_settings = *devices[i].output_settings;
    sinks.push_back(std::make_unique<SequencerSink>(sequencers.back().get(), device_index,
                                                    &options.sample_filter));
    std::string why;
    decoders.push_back(drivers::MakeDecoder(devices[i].protocol, d, sinks.back().get(), &why));
    if (!decoders.back()) {
      if (error) *error = fmt::format("device '{}': {}", devices[i].name, why);
      return false;
    }
  }
  drivers::CaptureRecord r;
  std::int64_t last_ns = 0;
  while (reader->Next(&r)) {
    const auto t_ns = static_cast<std::int64_t>(r.t_ns);
    last_ns = std::max(last_ns, t_ns);
    if (r.type == drivers::RecordType::kEvent) {
      const auto j = nlohmann::json::parse(r.payload.begin(), r.payload.end(), nullptr, false);
      Announcement a;
      bool is_pose = false;
      std::string why;
      const bool ok = protocol::ParsePoseCommand(j, t_ns, &a, &is_pose, &why);
      if (!is_pose) {
        ++result->ignored_events;
        continue;
      }
      ++result->pose_commands;
      if (!ok) {
        result->warnings.push_back(fmt::format("event at {:.3f} s: {}", t_ns * 1e-9, why));
        continue;
      }
      if (options.schedule) {
        ++result->ignored_events;
        continue;
      }
      for (auto& s : sequencers) {
        if (!s->Announce(a, &why)) {
          result->warnings.push_back(fmt::format("event at {:.3f} s: {}", t_ns * 1e-9, why));
        }
      }
      continue;
    }
    if (r.device >= decoders.size()) {
      result->warnings.push_back(
          fmt::format("a record names device {} of {}; skipped", r.device, decoders.size()));
      continue;
    }
    for (auto& s : sequencers) s->Tick(t_ns);
    if (r.type == drivers::RecordType::kReceived) decoders[r.device]->Push(r.payload, t_ns);
  }
  if (!reader->error().empty()) result->warnings.push_back(reader->error());
  if (reader->truncated()) {
    result->warnings.push_back(fmt::format("the capture ends inside a record ({} bytes ignored)",
                                           reader->trailing_bytes()));
  }
  for (std::size_t i = 0; i < devices.size(); ++i) {
    decoders[i]->Finish();
    sequencers[i]->Finish(last_ns);
    result->devices[i].decoder = decoders[i]->counters();
    result->devices[i].totals = sequencers[i]->totals();
    if (sequencers[i]->noise()) result->devices[i].noise = *sequencers[i]->noise();
  }
  return true;
}

}  // namespace turncal::daemon
