#pragma once
// A recording decorator on any transport (issue "Transports"): the bytes received and sent, and
// events, are appended to a capture as they pass, with host times since the recording began.
// Recording failures (a full disk) are reported once through the status handler and counted;
// the stream itself goes on.

#include <memory>

#include "drivers/capture/tcap.h"
#include "drivers/transport/transport.h"

namespace turncal::drivers {

class RecordingTransport final : public Transport {
 public:
  // `device` is the record's device index in the capture's header.
  // `start_ns` (MonotonicNowNs() clock) is time 0 of the records; several devices recording into
  // one capture share it, so their records keep their relative timing. < 0: now.
  RecordingTransport(std::unique_ptr<Transport> inner, CaptureWriter* writer, std::uint8_t device,
                     std::int64_t start_ns = -1);

  void Start(DataHandler on_data, StatusHandler on_status) override;
  void SetEventHandler(EventHandler on_event) override;
  bool Write(std::span<const std::uint8_t> bytes, std::string* error) override;
  void Stop() override { inner_->Stop(); }
  bool is_open() const override { return inner_->is_open(); }
  std::string Describe() const override { return inner_->Describe() + " (recording)"; }
  const TransportCounters& counters() const override { return inner_->counters(); }

  // An event (JSON) into the capture, e.g. a pose command. `t_host_ns` (MonotonicNowNs() clock) is
  // the time the event took effect, so that a replay sees it at the same point relative to the
  // samples as the live pipeline did; < 0: now.
  void RecordEvent(const std::string& json, std::int64_t t_host_ns = -1);
  std::uint64_t record_failures() const { return failures_; }

 private:
  // Received bytes are recorded with the time the transport handed to the pipeline (not a second
  // reading of the clock): a replay then decodes every sample with the host time it had live.
  void Append(RecordType type, std::span<const std::uint8_t> payload, std::int64_t t_host_ns);

  std::unique_ptr<Transport> inner_;
  CaptureWriter* writer_;
  std::uint8_t device_;
  std::int64_t start_ns_;
  StatusHandler on_status_;
  std::uint64_t failures_ = 0;
};

}  // namespace turncal::drivers
