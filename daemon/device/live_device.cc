#include "daemon/device/live_device.h"

#include <fmt/format.h>

#include <boost/asio/post.hpp>

#include "daemon/device/transport_link.h"
#include "drivers/decoder_factory.h"
#include "drivers/mip/mip_dialogue.h"
#include "drivers/mip/mip_stored.h"
#include "drivers/xbus/mtdata2.h"
#include "drivers/xbus/xbus_dialogue.h"

namespace turncal::daemon {

nlohmann::json MipIdentity(const drivers::mip::Configured& c, double rate_hz) {
  return {{"protocol", "mip"},
          {"model_name", c.info.model_name},
          {"model_number", c.info.model_number},
          {"serial", c.info.serial},
          {"lot", c.info.lot},
          {"options", c.info.options},
          {"firmware", c.info.firmware},
          {"base_rate_hz", c.base_rate_hz},
          {"decimation", c.decimation},
          {"rate_hz", rate_hz},
          // What the device applies itself before output (recorded with every calibration).
          {"stored_calibration", drivers::mip::StoredCalibrationJson(c.stored)}};
}

namespace {

// Counter and fine time at every sample, then the calibrated triads, temperature and status.
drivers::xbus::OutputConfiguration XbusOutputs(double rate_hz) {
  const auto rate = static_cast<std::uint16_t>(std::lround(rate_hz));
  namespace x = drivers::xbus;
  return {{x::kPacketCounter, 0xFFFF}, {x::kSampleTimeFine, 0xFFFF}, {x::kTemperature, rate},
          {x::kAcceleration, rate},    {x::kRateOfTurn, rate},       {x::kMagneticField, rate},
          {x::kStatusWord, rate}};
}

// The counters of a decoder replaced after a reconfiguration, kept in the device's totals.
void AddCounters(drivers::DecoderCounters* into, const drivers::DecoderCounters& c) {
  into->bytes_in += c.bytes_in;
  into->bytes_in_frames += c.bytes_in_frames;
  into->bad_structure += c.bad_structure;
  into->timeouts += c.timeouts;
  into->frames += c.frames;
  into->bad_checksums += c.bad_checksums;
  into->bytes_skipped += c.bytes_skipped;
  into->lost_samples += c.lost_samples;
  into->samples += c.samples;
}

}  // namespace

double DefaultRateHz(drivers::Protocol protocol) {
  return protocol == drivers::Protocol::kMip ? 500.0 : 100.0;
}

class LiveDevice::Sink final : public drivers::DecoderSink {
 public:
  explicit Sink(LiveDevice* device) : device_(device) {}
  void OnFrame(const drivers::FrameView&) override {}
  void OnSample(const Sample& sample) override {
    ++device_->samples_;
    ++device_->rate_samples_;
    device_->on_sample_(sample);
  }

 private:
  LiveDevice* device_;
};

LiveDevice::LiveDevice(boost::asio::io_context& io, drivers::DeviceSpec spec,
                       DeviceSettings settings, SampleHandler on_sample, NoticeHandler on_notice,
                       IdentityHandler on_identity)
    : io_(io),
      spec_(std::move(spec)),
      settings_(settings),
      on_sample_(std::move(on_sample)),
      on_notice_(std::move(on_notice)),
      on_identity_(std::move(on_identity)),
      sink_(std::make_unique<Sink>(this)),
      retry_timer_(io) {
  if (!(settings_.rate_hz > 0)) settings_.rate_hz = DefaultRateHz(spec_.protocol);
}

LiveDevice::~LiveDevice() {
  Stop();
  JoinWorker();
  *alive_ = false;  // a dialogue's result still queued on the loop must not touch this device
}

void LiveDevice::JoinWorker() {
  if (link_) link_->Close("turncald is stopping");
  if (worker_.joinable()) worker_.join();
}

bool LiveDevice::Start(std::string* error) {
  drivers::TransportOptions options;
  options.reconnect_max = settings_.reconnect_max;
  transport_ = drivers::MakeTransport(io_, spec_.port, spec_.baud, options, error);
  if (!transport_) return false;
  if (recorder_) {
    auto recording = std::make_unique<drivers::RecordingTransport>(std::move(transport_), recorder_,
                                                                   record_index_, record_start_ns_);
    recording_ = recording.get();
    transport_ = std::move(recording);
  }
  stopping_ = false;
  if (on_capture_event_) transport_->SetEventHandler(on_capture_event_);
  SetState("info", "opening", "opening " + transport_->Describe());
  transport_->Start(
      [this](std::span<const std::uint8_t> bytes, std::int64_t t) { OnData(bytes, t); },
      [this](drivers::TransportStatus s, const std::string& m) { OnTransportStatus(s, m); });
  return true;
}

void LiveDevice::RecordEvent(const std::string& json, std::int64_t t_host_ns) {
  if (recording_) recording_->RecordEvent(json, t_host_ns);
}

void LiveDevice::Stop() {
  if (stopping_) return;
  stopping_ = true;
  ++generation_;
  retry_timer_.cancel();
  if (link_) link_->Close("turncald is stopping");
  if (transport_) transport_->Stop();
  if (decoder_) decoder_->Finish();
  state_ = "stopped";
}

void LiveDevice::SetState(const std::string& level, std::string state, std::string message) {
  state_ = std::move(state);
  message_ = std::move(message);
  if (on_notice_) on_notice_(level, state_, message_);
}

void LiveDevice::OnTransportStatus(drivers::TransportStatus status, const std::string& message) {
  if (stopping_) return;
  attempted_ = true;
  switch (status) {
    case drivers::TransportStatus::kOpened:
      if (spec_.protocol == drivers::Protocol::kGx2 || !settings_.configure ||
          spec_.port.rfind("replay:", 0) == 0) {
        const char* why = spec_.protocol == drivers::Protocol::kGx2 ? " (gx2: no dialogue)"
                          : !settings_.configure                    ? " (configure = false)"
                                                 : " (a replay: its dialogue is in the capture)";
        SetState("info", "streaming", message + why);
        StartStreaming(std::nullopt);
      } else {
        SetState("info", "configuring", message);
        BeginConfigure();
      }
      break;
    case drivers::TransportStatus::kOpenFailed:
      SetState("warn", "opening", message);
      break;
    case drivers::TransportStatus::kDisconnected:
      ++generation_;
      retry_timer_.cancel();
      if (link_) link_->Close(message);
      if (decoder_) {
        decoder_->Finish();
        AddCounters(&retired_, decoder_->counters());
        decoder_.reset();
      }
      SetState("error", "disconnected", message);
      break;
    case drivers::TransportStatus::kFinished:
      if (decoder_) decoder_->Finish();
      SetState("info", "finished", message);
      break;
    case drivers::TransportStatus::kRecordingFailed:
      SetState("warn", state_, message);
      break;
    case drivers::TransportStatus::kStopped:
      break;
  }
}

void LiveDevice::OnData(std::span<const std::uint8_t> bytes, std::int64_t t_host_ns) {
  if (decoder_) {
    decoder_->Push(bytes, t_host_ns);
    return;
  }
  if (link_ && (state_ == "configuring" || state_ == "writing")) {
    bytes_dialogue_ += bytes.size();
    link_->Deliver(bytes);
    return;
  }
  bytes_ignored_ += bytes.size();  // between a failed dialogue and its retry
}

void LiveDevice::BeginConfigure() {
  JoinWorker();  // an earlier dialogue has ended (its result was dropped) or is told to end
  link_ = std::make_shared<TransportLink>(io_, transport_.get());
  RecordEvent(R"({"event":"dialogue","state":"begin"})");
  const std::uint64_t generation = ++generation_;
  const drivers::Protocol protocol = spec_.protocol;
  const double rate_hz = settings_.rate_hz;
  std::shared_ptr<TransportLink> link = link_;
  worker_ = std::thread([this, alive = alive_, link, generation, protocol, rate_hz] {
    std::string error;
    nlohmann::json identity;
    std::optional<drivers::XbusLegacyLayout> layout;
    bool ok = false;
    if (protocol == drivers::Protocol::kMip) {
      drivers::mip::Dialogue dialogue(link.get());
      if (auto c = dialogue.Configure(rate_hz, &error)) {
        identity = MipIdentity(*c, c->base_rate_hz / static_cast<double>(c->decimation));
        ok = true;
      }
    } else {
      drivers::xbus::Dialogue dialogue(link.get());
      const bool legacy = protocol == drivers::Protocol::kXbusLegacy;
      std::optional<drivers::xbus::DeviceIdentity> id;
      if (legacy) {
        if (dialogue.GoToConfig(&error) && (id = dialogue.Identify(&error)) &&
            (layout = dialogue.ReadLegacyLayout(&error)) && dialogue.GoToMeasurement(&error)) {
          ok = true;
        }
      } else if ((id = dialogue.Configure(XbusOutputs(rate_hz), &error))) {
        ok = true;
      }
      if (ok) {
        identity = {{"protocol", drivers::ToString(protocol)},
                    {"device_id", fmt::format("{:08X}", id->device_id)},
                    {"product_code", id->product_code},
                    {"firmware", id->firmware},
                    {"rate_hz", rate_hz}};
        if (layout) {
          identity["output_mode"] = fmt::format("0x{:04X}", layout->output_mode);
          identity["output_settings"] = fmt::format("0x{:08X}", layout->output_settings);
        }
      }
    }
    boost::asio::post(io_, [this, alive, generation, ok, error, identity, layout] {
      // The device was destroyed (a reload) or went away meanwhile.
      if (!*alive || generation != generation_) return;
      EndConfigure(ok, error, identity, layout);
    });
  });
}

bool LiveDevice::RunStoredWrite(std::vector<drivers::mip::StoredWriteStep> steps, bool save,
                                StoredWriteDone done, std::string* error) {
  if (spec_.protocol != drivers::Protocol::kMip) {
    *error = spec_.name + " is not a MIP device";
    return false;
  }
  if (!settings_.configure || spec_.port.rfind("replay:", 0) == 0) {
    *error = spec_.name + (settings_.configure ? " replays a capture"
                                               : " is not configured by "
                                                 "turncald (configure = "
                                                 "false)");
    return false;
  }
  if (state_ != "streaming" || !transport_ || !transport_->is_open()) {
    *error = fmt::format("{} is {}, not streaming", spec_.name, state_);
    return false;
  }
  // The decoder ends here; the dialogue reads the device's bytes until it streams again.
  if (decoder_) {
    decoder_->Finish();
    AddCounters(&retired_, decoder_->counters());
    decoder_.reset();
  }
  JoinWorker();
  link_ = std::make_shared<TransportLink>(io_, transport_.get());
  ++stored_writes_;
  SetState("info", "writing",
           fmt::format("writing a stored calibration ({} quantities{})", steps.size(),
                       save ? ", saved" : ""));
  RecordEvent(R"({"event":"dialogue","state":"begin"})");
  const std::uint64_t generation = ++generation_;
  const double rate_hz = settings_.rate_hz;
  std::shared_ptr<TransportLink> link = link_;
  worker_ = std::thread([this, alive = alive_, link, generation, rate_hz, steps = std::move(steps),
                         save, done = std::move(done)] {
    drivers::mip::Dialogue dialogue(link.get());
    drivers::mip::StoredWriteOutcome outcome =
        drivers::mip::WriteStoredCalibration(&dialogue, steps, save);
    std::string configure_error;
    nlohmann::json identity;
    if (auto c = dialogue.Configure(rate_hz, &configure_error)) {
      identity = MipIdentity(*c, c->base_rate_hz / static_cast<double>(c->decimation));
    }
    boost::asio::post(io_, [this, alive, generation, outcome = std::move(outcome), identity,
                            configure_error, done] {
      // The write's outcome is reported whatever became of the device since.
      if (done) done(outcome, identity, identity.is_null() ? configure_error : std::string());
      // The device was destroyed (a reload) or went away meanwhile.
      if (!*alive || generation != generation_) return;
      EndConfigure(!identity.is_null(), configure_error, identity, std::nullopt);
    });
  });
  return true;
}

void LiveDevice::EndConfigure(bool ok, const std::string& error, nlohmann::json identity,
                              std::optional<drivers::XbusLegacyLayout> layout) {
  if (!ok) {
    ++configure_failures_;
    SetState("error", "configure failed",
             fmt::format("{}: {}; retrying in {} s", spec_.name, error,
                         static_cast<double>(settings_.configure_retry.count()) / 1000.0));
    link_->Close("the dialogue failed");
    const std::uint64_t generation = generation_;
    retry_timer_.expires_after(settings_.configure_retry);
    retry_timer_.async_wait([this, generation](const boost::system::error_code& ec) {
      if (ec || stopping_ || generation != generation_ || !transport_->is_open()) return;
      SetState("info", "configuring", "retrying the configuration dialogue");
      BeginConfigure();
    });
    return;
  }
  identity_ = std::move(identity);
  link_->Close("configured");
  if (on_identity_) on_identity_(identity_);
  SetState("info", "streaming", "configured: " + identity_.dump());
  StartStreaming(layout);
}

void LiveDevice::StartStreaming(std::optional<drivers::XbusLegacyLayout> layout) {
  RecordEvent(R"({"event":"dialogue","state":"end"})");
  drivers::DecoderOptions options;
  options.device = spec_.name;
  if (layout) options.xbus_legacy = *layout;
  std::string error;
  decoder_ = drivers::MakeDecoder(spec_.protocol, options, sink_.get(), &error);
  if (!decoder_) SetState("error", "configure failed", spec_.name + ": " + error);
}

void LiveDevice::UpdateRate(std::int64_t now_ns) {
  if (rate_t_ns_ > 0 && now_ns > rate_t_ns_) {
    rate_hz_ = static_cast<double>(rate_samples_) * 1e9 / static_cast<double>(now_ns - rate_t_ns_);
  }
  rate_t_ns_ = now_ns;
  rate_samples_ = 0;
  // No decoder->CheckTimeout(now) here: the decoder judges timeouts on the bytes' arrival times
  // (a loop that is late to read must not drop a frame whose rest waits in the kernel).
}

nlohmann::json LiveDevice::Status() const {
  drivers::DecoderCounters c = retired_;
  if (decoder_) AddCounters(&c, decoder_->counters());
  const drivers::TransportCounters t =
      transport_ ? transport_->counters() : drivers::TransportCounters{};
  return {{"name", spec_.name},
          {"protocol", drivers::ToString(spec_.protocol)},
          {"port", spec_.port},
          {"baud", spec_.baud},
          {"state", state_},
          {"message", message_},
          {"identity", identity_},
          {"rate_hz", rate_hz_},
          {"configured_rate_hz", settings_.rate_hz},
          {"counters",
           {{"bytes_read", t.bytes_read},
            {"bytes_written", t.bytes_written},
            {"opens", t.opens},
            {"open_failures", t.open_failures},
            {"disconnects", t.disconnects},
            {"configure_failures", configure_failures_},
            {"stored_writes", stored_writes_},
            {"bytes_ignored", bytes_ignored_},
            // Every byte read is accounted for: bytes_read = bytes_dialogue + bytes_ignored +
            // bytes_decoded, and bytes_decoded = bytes_in_frames + skipped_bytes + pending_bytes.
            {"bytes_dialogue", bytes_dialogue_},
            {"bytes_decoded", c.bytes_in},
            {"bytes_in_frames", c.bytes_in_frames},
            {"pending_bytes", decoder_ ? decoder_->pending_bytes() : 0},
            {"bad_structure", c.bad_structure},
            {"timeouts", c.timeouts},
            {"frames", c.frames},
            {"samples", c.samples},
            {"bad_checksums", c.bad_checksums},
            {"skipped_bytes", c.bytes_skipped},
            {"lost_samples", c.lost_samples}}}};
}

}  // namespace turncal::daemon
