#include "tools/capture_command.h"

#include <fmt/format.h>

#include <boost/asio/io_context.hpp>
#include <boost/asio/signal_set.hpp>
#include <boost/asio/steady_timer.hpp>
#include <ctime>
#include <nlohmann/json.hpp>

#include "drivers/decoder_factory.h"
#include "drivers/transport/recording.h"
#include "tools/help_text.h"

namespace turncal::tools {

namespace {

class CountingSink : public drivers::DecoderSink {
 public:
  void OnFrame(const drivers::FrameView&) override {}
  void OnSample(const Sample&) override {}
};

// The codes RunCapture returns.
constexpr Manual kCaptureManual = {
    "Records a live port into a .tcap capture (bytes with their host times) until Ctrl-C or "
    "SIGTERM. A capture replays through the whole pipeline: turncald --replay FILE --once.",
    "turncal capture --device imu=mip:/dev/ttyUSB0@921600 -o session.tcap\n"
    "turncal capture --device imu=xbus:tcp://10.0.0.5:4001 -o xsens.tcap --note \"bench 2\"",
    "0 when stopped by a signal; 1 the port failed; 2 a command-line mistake",
    "docs/capture-format.md"};

int RunCapture(const std::string& spec_text, const std::string& output, const std::string& note) {
  std::string error;
  const auto spec = drivers::ParseDeviceSpec(spec_text, &error);
  if (!spec) {
    fmt::print(stderr, "turncal capture: {}\n", error);
    return 2;
  }
  drivers::CaptureHeader header;
  header.devices.push_back({spec->name, spec->protocol, spec->baud, std::nullopt, std::nullopt});
  header.created = drivers::UtcNowIso8601();
  header.note = note;
  auto writer = drivers::CaptureWriter::Create(output, header, &error);
  if (!writer) {
    fmt::print(stderr, "turncal capture: {}\n", error);
    return 2;
  }
  boost::asio::io_context io;
  drivers::TransportOptions options;
  options.two_stop_bits = spec->protocol == drivers::Protocol::kXbusLegacy;
  auto inner = drivers::MakeTransport(io, spec->port, spec->baud, options, &error);
  if (!inner) {
    fmt::print(stderr, "turncal capture: {}\n", error);
    return 2;
  }
  drivers::RecordingTransport transport(std::move(inner), writer.get(), 0);
  // Decode as we go, for the progress line (bad frames show a wrong protocol or baud at once).
  CountingSink sink;
  drivers::DecoderOptions decoder_options;
  decoder_options.device = spec->name;
  auto decoder = drivers::MakeDecoder(spec->protocol, decoder_options, &sink, &error);
  if (!decoder) {
    fmt::print(stderr, "turncal capture: {}\n", error);
    return 2;
  }
  // A replayed capture's events are recorded too (the recording decorator appends them).
  transport.SetEventHandler([](const std::string&, std::int64_t) {});
  transport.Start([&](std::span<const std::uint8_t> b, std::int64_t t) { decoder->Push(b, t); },
                  [&](drivers::TransportStatus s, const std::string& m) {
                    fmt::print(stderr, "turncal capture: {}: {}\n", drivers::ToString(s), m);
                    if (s == drivers::TransportStatus::kFinished) io.stop();
                  });
  boost::asio::signal_set signals(io, SIGINT, SIGTERM);
  signals.async_wait([&](const boost::system::error_code&, int signal) {
    fmt::print(stderr, "turncal capture: signal {}: closing {}\n", signal, output);
    io.stop();
  });
  boost::asio::steady_timer progress(io);
  std::function<void()> tick = [&] {
    progress.expires_after(std::chrono::seconds(1));
    progress.async_wait([&](const boost::system::error_code& ec) {
      if (ec) return;
      const auto& c = decoder->counters();
      std::string flush_error;
      if (!writer->Flush(&flush_error)) {
        fmt::print(stderr, "\nturncal capture: {}; stopping\n", flush_error);
        io.stop();
        return;
      }
      fmt::print(stderr, "\rturncal capture: {} bytes, {} frames, {} samples, {} bad checksums   ",
                 c.bytes_in, c.frames, c.samples, c.bad_checksums);
      tick();
    });
  };
  tick();
  io.run();
  transport.Stop();
  if (!writer->Close(&error)) {
    fmt::print(stderr, "\nturncal capture: {}\n", error);
    return 1;
  }
  fmt::print(stderr, "\nturncal capture: {} records written to {}\n", writer->records(), output);
  return 0;
}

int RunDevices(bool json) {
  std::string error;
  const auto ports = drivers::ListSerialPorts(&error);
  if (!error.empty()) {
    fmt::print(stderr, "turncal devices: {}\n", error);
    return 2;  // as a daemon that cannot be reached (client_commands.cc, kDevicesManual)
  }
  for (const auto& p : ports) {
    if (json) {
      nlohmann::json j = {{"class", "PORT"},
                          {"name", p.name},
                          {"description", p.description},
                          {"transport", p.transport}};
      if (p.usb_vid >= 0) {
        j["usb_vid"] = fmt::format("{:04x}", p.usb_vid);
        j["usb_pid"] = fmt::format("{:04x}", p.usb_pid);
        j["usb_serial"] = p.usb_serial;
        j["manufacturer"] = p.manufacturer;
        j["product"] = p.product;
      }
      fmt::print("{}\n", j.dump());
    } else {
      fmt::print("{:<20} {:<9} {}{}\n", p.name, p.transport, p.description,
                 p.usb_vid >= 0 ? fmt::format("  [usb {:04x}:{:04x} serial {}]", p.usb_vid,
                                              p.usb_pid, p.usb_serial)
                                : "");
    }
  }
  if (!json && ports.empty()) fmt::print("no serial ports found\n");
  return 0;
}

}  // namespace

int RunLocalDevices(bool json) { return RunDevices(json); }

void AddCaptureCommands(CLI::App* app) {
  auto spec = std::make_shared<std::string>();
  auto output = std::make_shared<std::string>();
  auto note = std::make_shared<std::string>();
  auto* cmd = app->add_subcommand(
      "capture", "record a live port into a .tcap capture until SIGINT/SIGTERM (Ctrl-C)");
  SetManual(cmd, kCaptureManual);
  cmd->add_option("--device", *spec, "NAME=PROTOCOL:PORT[@BAUD]")->required();
  cmd->add_option("-o,--output", *output, "the capture to write")->required();
  cmd->add_option("--note", *note, "free text stored in the capture's header");
  cmd->callback(
      [spec, output, note] { throw CLI::RuntimeError(RunCapture(*spec, *output, *note)); });
}

}  // namespace turncal::tools
