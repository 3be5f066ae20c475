#pragma once
// Where bytes come from (issue "Transports"): one interface over real serial ports
// (libserialport; a termios backend for pseudo-terminals), serial device servers (tcp://) and
// replayed captures (replay:FILE). Reads are asynchronous on a Boost.Asio io_context and never
// block; a device that goes away (EOF, EIO, a closed connection) is reopened with backoff, and
// every change is reported through the status handler with a message a log can carry.

#include <boost/asio/io_context.hpp>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>

#include "drivers/device_spec.h"

namespace turncal::drivers {

enum class TransportStatus {
  kOpened,        // the message says how (e.g. "libserialport" or "termios (pseudo-terminal)")
  kOpenFailed,    // will retry
  kDisconnected,  // the device went away (EOF/EIO/reset); will reopen
  kStopped,
  kFinished,         // a replay reached its end
  kRecordingFailed,  // a recording decorator could not write its capture (the stream goes on)
};
const char* ToString(TransportStatus status);

struct TransportCounters {
  std::uint64_t bytes_read = 0;
  std::uint64_t bytes_written = 0;
  std::uint64_t opens = 0;
  std::uint64_t open_failures = 0;
  std::uint64_t disconnects = 0;
};

struct TransportOptions {
  std::chrono::milliseconds reconnect_initial{100};
  std::chrono::milliseconds reconnect_max{5000};
  bool two_stop_bits = false;  // 8N2 (older Xsens MTi/MTx)
};

class Transport {
 public:
  using DataHandler = std::function<void(std::span<const std::uint8_t>, std::int64_t t_host_ns)>;
  using StatusHandler = std::function<void(TransportStatus, const std::string& message)>;
  // Replay only: events recorded in the capture, at their time.
  using EventHandler = std::function<void(const std::string& json, std::int64_t t_host_ns)>;

  virtual ~Transport() = default;
  // Opens (retrying with backoff) and reads until Stop(); handlers run on the io_context.
  virtual void Start(DataHandler on_data, StatusHandler on_status) = 0;
  virtual void SetEventHandler(EventHandler) {}
  // Writes all bytes now (commands are short); false with a message when the device is not open
  // or the write fails.
  virtual bool Write(std::span<const std::uint8_t> bytes, std::string* error) = 0;
  virtual void Stop() = 0;
  virtual bool is_open() const = 0;
  virtual std::string Describe() const = 0;
  virtual const TransportCounters& counters() const = 0;
};

// Host monotonic time in nanoseconds (the receive-time stamp of every chunk).
std::int64_t MonotonicNowNs();
// The wall clock as UTC, ISO 8601 to the second ("2026-11-22T15:16:05Z"): the time stamps of
// calibrations, reports and capture headers.
std::string UtcNowIso8601();

// The transport for a PORT of DESIGN.md: a device path, tcp://HOST:PORT or
// replay:FILE[?speed=X|max].
std::unique_ptr<Transport> MakeTransport(boost::asio::io_context& io, const std::string& port,
                                         int baud, const TransportOptions& options,
                                         std::string* error);

// Serial ports libserialport can see, with USB identity where it has one.
struct PortInfo {
  std::string name;
  std::string description;
  std::string transport;  // "usb", "native", "bluetooth"
  int usb_vid = -1, usb_pid = -1;
  std::string usb_serial, manufacturer, product;
};
std::vector<PortInfo> ListSerialPorts(std::string* error);

}  // namespace turncal::drivers
