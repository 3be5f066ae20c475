#include "drivers/transport/transport.h"

#include <libserialport.h>
#include <time.h>

#include <ctime>

#include "drivers/transport/transport_impl.h"

namespace turncal::drivers {

const char* ToString(TransportStatus s) {
  switch (s) {
    case TransportStatus::kOpened:
      return "opened";
    case TransportStatus::kOpenFailed:
      return "open failed";
    case TransportStatus::kDisconnected:
      return "disconnected";
    case TransportStatus::kStopped:
      return "stopped";
    case TransportStatus::kFinished:
      return "finished";
    case TransportStatus::kRecordingFailed:
      return "recording failed";
  }
  return "?";
}

std::int64_t MonotonicNowNs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

std::string UtcNowIso8601() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  char text[32];
  std::strftime(text, sizeof(text), "%Y-%m-%dT%H:%M:%SZ", &tm);
  return text;
}

std::unique_ptr<Transport> MakeTransport(boost::asio::io_context& io, const std::string& port,
                                         int baud, const TransportOptions& options,
                                         std::string* error) {
  if (port.rfind("tcp://", 0) == 0) {
    const std::string rest = port.substr(6);
    const auto colon = rest.rfind(':');
    if (colon == std::string::npos || colon == 0 || colon + 1 == rest.size()) {
      if (error) *error = "tcp port must be tcp://HOST:PORT, got '" + port + "'";
      return nullptr;
    }
    return MakeTcpTransport(io, rest.substr(0, colon), rest.substr(colon + 1), options);
  }
  if (port.rfind("replay:", 0) == 0) {
    std::string file = port.substr(7);
    double speed = 1.0;
    const auto q = file.find("?speed=");
    if (q != std::string::npos) {
      const std::string value = file.substr(q + 7);
      file = file.substr(0, q);
      if (value == "max") {
        speed = 0.0;
      } else {
        try {
          std::size_t used = 0;
          speed = std::stod(value, &used);
          if (used != value.size() || !(speed > 0)) throw std::invalid_argument(value);
        } catch (const std::exception&) {
          if (error)
            *error = "replay speed must be a positive number or 'max', got '" + value + "'";
          return nullptr;
        }
      }
    }
    return MakeReplayTransport(io, file, speed, error);
  }
  if (port.empty()) {
    if (error) *error = "empty port";
    return nullptr;
  }
  if (!(baud > 0)) {
    if (error) *error = "baud must be > 0";
    return nullptr;
  }
  return MakeSerialTransport(io, port, baud, options);
}

std::vector<PortInfo> ListSerialPorts(std::string* error) {
  std::vector<PortInfo> out;
  sp_port** ports = nullptr;
  if (sp_list_ports(&ports) != SP_OK) {
    if (error) *error = "libserialport cannot list ports";
    return out;
  }
  auto str = [](const char* s) { return s ? std::string(s) : std::string(); };
  for (int i = 0; ports[i] != nullptr; ++i) {
    PortInfo p;
    p.name = str(sp_get_port_name(ports[i]));
    p.description = str(sp_get_port_description(ports[i]));
    const auto t = sp_get_port_transport(ports[i]);
    p.transport = t == SP_TRANSPORT_USB         ? "usb"
                  : t == SP_TRANSPORT_BLUETOOTH ? "bluetooth"
                                                : "native";
    if (t == SP_TRANSPORT_USB) {
      sp_get_port_usb_vid_pid(ports[i], &p.usb_vid, &p.usb_pid);
      p.usb_serial = str(sp_get_port_usb_serial(ports[i]));
      p.manufacturer = str(sp_get_port_usb_manufacturer(ports[i]));
      p.product = str(sp_get_port_usb_product(ports[i]));
    }
    out.push_back(p);
  }
  sp_free_port_list(ports);
  return out;
}

}  // namespace turncal::drivers
