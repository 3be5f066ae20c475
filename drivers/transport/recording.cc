#include "drivers/transport/recording.h"

namespace turncal::drivers {

RecordingTransport::RecordingTransport(std::unique_ptr<Transport> inner, CaptureWriter* writer,
                                       std::uint8_t device, std::int64_t start_ns)
    : inner_(std::move(inner)),
      writer_(writer),
      device_(device),
      start_ns_(start_ns >= 0 ? start_ns : MonotonicNowNs()) {}

void RecordingTransport::Append(RecordType type, std::span<const std::uint8_t> payload,
                                std::int64_t t_host_ns) {
  const auto since_ns =
      static_cast<std::uint64_t>(std::max<std::int64_t>(0, t_host_ns - start_ns_));
  std::string error;
  if (!writer_->Append(type, device_, since_ns, payload, &error)) {
    if (failures_++ == 0 && on_status_) {
      on_status_(TransportStatus::kRecordingFailed, Describe() + ": " + error);
    }
  }
}

void RecordingTransport::Start(DataHandler on_data, StatusHandler on_status) {
  on_status_ = on_status;
  inner_->Start(
      [this, on_data = std::move(on_data)](std::span<const std::uint8_t> bytes, std::int64_t t) {
        Append(RecordType::kReceived, bytes, t);
        on_data(bytes, t);
      },
      std::move(on_status));
}

void RecordingTransport::SetEventHandler(EventHandler on_event) {
  inner_->SetEventHandler(
      [this, on_event = std::move(on_event)](const std::string& json, std::int64_t t) {
        RecordEvent(json, t);
        if (on_event) on_event(json, t);
      });
}

bool RecordingTransport::Write(std::span<const std::uint8_t> bytes, std::string* error) {
  const bool ok = inner_->Write(bytes, error);
  if (ok) Append(RecordType::kSent, bytes, MonotonicNowNs());
  return ok;
}

void RecordingTransport::RecordEvent(const std::string& json, std::int64_t t_host_ns) {
  Append(RecordType::kEvent,
         std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(json.data()),
                                       json.size()),
         t_host_ns >= 0 ? t_host_ns : MonotonicNowNs());
}

}  // namespace turncal::drivers
