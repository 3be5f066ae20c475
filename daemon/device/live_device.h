#pragma once
// One live device of a station: its transport (opened and reopened with backoff), its
// configuration dialogue (idle, identify, output format and rate, the device's stored
// calibration, stream) on a worker thread so the loop never waits for a reply, then its decoder.
// A device that is absent or whose dialogue fails is reported and retried; the others go on.
//
// States: "opening" → "configuring" → "streaming"; "configure failed" (retried after
// `configure_retry`), "disconnected" (reopened by the transport), "stopped"; "writing" while a
// stored calibration is written into a MIP device (RunStoredWrite), then "configuring" again.

#include <boost/asio/io_context.hpp>
#include <boost/asio/steady_timer.hpp>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>

#include "core/sequencing/sample.h"
#include "daemon/device/writable_device.h"
#include "drivers/decoder.h"
#include "drivers/device_spec.h"
#include "drivers/mip/mip_dialogue.h"
#include "drivers/mip/mip_stored_write.h"
#include "drivers/transport/recording.h"
#include "drivers/transport/transport.h"
#include "drivers/xbus/xbus_decoder.h"

namespace turncal::daemon {

class TransportLink;

struct DeviceSettings {
  double rate_hz = 0.0;   // output rate asked for in the dialogue; <= 0: the protocol's default
  bool configure = true;  // false: listen only (a device configured elsewhere)
  std::chrono::milliseconds configure_retry{5000};
  std::chrono::milliseconds reconnect_max{5000};
};

// The rate the dialogue asks for when none is configured: mip 500 Hz, the others 100 Hz (the
// simulator's defaults, and what SENSORS.md's link budgets carry at the default bauds).
double DefaultRateHz(drivers::Protocol protocol);

// What a MIP device's configuration dialogue learnt of it, as LiveDevice reports its identity
// ({"protocol":"mip","model_name",...,"serial",...,"rate_hz","stored_calibration"}).
nlohmann::json MipIdentity(const drivers::mip::Configured& configured, double rate_hz);

class LiveDevice : public WritableDevice {
 public:
  using SampleHandler = std::function<void(const Sample&)>;
  // A state change or a problem, in a sentence a log can carry; `level` "info", "warn", "error".
  using NoticeHandler =
      std::function<void(const std::string& level, const std::string& state, const std::string&)>;
  // Runs on the loop when a dialogue succeeded: what the device said about itself.
  using IdentityHandler = std::function<void(const nlohmann::json& identity)>;

  LiveDevice(boost::asio::io_context& io, drivers::DeviceSpec spec, DeviceSettings settings,
             SampleHandler on_sample, NoticeHandler on_notice, IdentityHandler on_identity);
  ~LiveDevice() override;  // stops, and joins a dialogue still running
  LiveDevice(const LiveDevice&) = delete;
  LiveDevice& operator=(const LiveDevice&) = delete;

  // replay: ports only: the capture's events (pose commands), at their time. Before Start().
  void SetCaptureEventHandler(drivers::Transport::EventHandler handler) {
    on_capture_event_ = std::move(handler);
  }
  // Records the device's bytes (both ways) as device `index` of `writer` (--record). Before
  // Start(); the writer must outlive the device.
  void RecordInto(drivers::CaptureWriter* writer, std::uint8_t index, std::int64_t start_ns) {
    recorder_ = writer;
    record_index_ = index;
    record_start_ns_ = start_ns;
  }
  // An event (a pose command) into the recording, at the device's recording clock.
  void RecordEvent(const std::string& json, std::int64_t t_host_ns = -1);
  // False with a message when the port cannot be used at all (a malformed tcp:// address).
  bool Start(std::string* error);
  void Stop();

  // Writes a stored calibration into a streaming MIP device (drivers/mip/mip_stored_write.h) on the
  // worker thread, then configures it again (its identity then carries what it stores). `done`
  // runs on the loop with the outcome and the identity after it (null with `configure_error`
  // when the dialogue after the write failed: the device is then retried as after any failed
  // dialogue), before the device streams again and its identity handler runs. False with a
  // message when the device is not a streaming, configured MIP device.
  bool RunStoredWrite(std::vector<drivers::mip::StoredWriteStep> steps, bool save,
                      StoredWriteDone done, std::string* error) override;

  const drivers::DeviceSpec& spec() const override { return spec_; }
  const std::string& state() const override { return state_; }
  nlohmann::json identity() const override { return identity_; }
  // {"name","protocol","port","baud","state","message","identity","rate_hz","counters":{...}}
  nlohmann::json Status() const;
  // Called once a second by the service: measures the sample rate.
  void UpdateRate(std::int64_t now_ns);
  std::uint64_t samples() const { return samples_; }
  // The first open attempt has finished (opened, or failed and retrying): for READY=1.
  bool attempted() const { return attempted_; }

 private:
  class Sink;
  void OnData(std::span<const std::uint8_t> bytes, std::int64_t t_host_ns);
  void OnTransportStatus(drivers::TransportStatus status, const std::string& message);
  void BeginConfigure();
  void EndConfigure(bool ok, const std::string& error, nlohmann::json identity,
                    std::optional<drivers::XbusLegacyLayout> layout);
  void StartStreaming(std::optional<drivers::XbusLegacyLayout> layout);
  void SetState(const std::string& level, std::string state, std::string message);
  void JoinWorker();

  boost::asio::io_context& io_;
  drivers::DeviceSpec spec_;
  DeviceSettings settings_;
  SampleHandler on_sample_;
  NoticeHandler on_notice_;
  IdentityHandler on_identity_;
  drivers::Transport::EventHandler on_capture_event_;
  drivers::CaptureWriter* recorder_ = nullptr;
  std::uint8_t record_index_ = 0;
  std::int64_t record_start_ns_ = -1;
  drivers::RecordingTransport* recording_ = nullptr;  // inside transport_, when recording
  std::unique_ptr<drivers::Transport> transport_;
  std::unique_ptr<Sink> sink_;
  std::unique_ptr<drivers::Decoder> decoder_;
  drivers::DecoderCounters retired_;  // counters of decoders replaced after a reconfiguration
  std::shared_ptr<TransportLink> link_;
  std::thread worker_;
  boost::asio::steady_timer retry_timer_;
  std::uint64_t generation_ = 0;  // a dialogue's result is dropped when the device moved on
  std::string state_ = "stopped";
  std::string message_;
  nlohmann::json identity_;
  std::uint64_t samples_ = 0, bytes_ignored_ = 0, configure_failures_ = 0, stored_writes_ = 0;
  std::uint64_t bytes_dialogue_ = 0;  // delivered to a configuration dialogue
  std::uint64_t rate_samples_ = 0;
  std::int64_t rate_t_ns_ = 0;
  double rate_hz_ = 0.0;
  bool stopping_ = false;
  bool attempted_ = false;
  // False once destroyed: a dialogue's result posted to the loop checks it before it touches the
  // device (the service destroys its devices on a reload while the loop runs on).
  std::shared_ptr<bool> alive_ = std::make_shared<bool>(true);
};

}  // namespace turncal::daemon
