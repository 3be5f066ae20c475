#include "tools/decode_command.h"

#include <fmt/format.h>

#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>

#include "drivers/capture/tcap.h"
#include "drivers/decoder_factory.h"
#include "drivers/xbus/xbus_encoder.h"
#include "tools/help_text.h"

namespace turncal::tools {

namespace {

struct DecodeArgs {
  std::string file;
  std::string protocol;
  bool json = false;
  double gx2_ticks_per_s = 19'660'800.0;
  bool gx2_little_endian = false;
  std::string legacy_mode;      // empty: from the capture header, else 0x0002
  std::string legacy_settings;  // empty: from the capture header, else 0x00000001
  std::size_t chunk = 4096;
};

const char* ToString(VectorFrame f) {
  switch (f) {
    case VectorFrame::kEnu:
      return "ENU";
    case VectorFrame::kNed:
      return "NED";
    case VectorFrame::kNwu:
      return "NWU";
    default:
      return "unknown";
  }
}

std::vector<std::string> FlagNames(std::uint32_t flags) {
  std::vector<std::string> out;
  for (const auto& f : kSampleFlagNames) {
    if (flags & f.flag) out.push_back(f.name);
  }
  return out;
}

class PrintingSink : public drivers::DecoderSink {
 public:
  PrintingSink(drivers::Protocol protocol, bool json) : protocol_(protocol), json_(json) {}

  void OnFrame(const drivers::FrameView& f) override {
    if (f.carries_sample) return;  // its sample is printed
    nlohmann::json j = {{"class", "FRAME"},
                        {"protocol", drivers::ToString(protocol_)},
                        {"kind", fmt::format("0x{:02X}", f.kind)},
                        {"length", f.bytes.size()}};
    std::string text = fmt::format("FRAME  {:<11} kind 0x{:02X} {:>4} bytes",
                                   drivers::ToString(protocol_), f.kind, f.bytes.size());
    if (protocol_ == drivers::Protocol::kMip) {
      std::vector<std::string> fields;
      for (std::size_t at = 4; at < 4u + f.bytes[3]; at += f.bytes[at]) {
        fields.push_back(fmt::format("{:02X}", f.bytes[at + 1]));
        if (f.bytes[at + 1] == 0xF1 && f.bytes[at] >= 4) {
          j["reply_to"] = fmt::format("0x{:02X}", f.bytes[at + 2]);
          j["reply_code"] = f.bytes[at + 3];
          text += fmt::format("  reply to 0x{:02X}: code {}", f.bytes[at + 2], f.bytes[at + 3]);
        }
      }
      j["fields"] = fields;
      text += "  fields";
      for (const auto& s : fields) text += " " + s;
    } else if (protocol_ == drivers::Protocol::kXbus ||
               protocol_ == drivers::Protocol::kXbusLegacy) {
      const auto payload = drivers::XbusDecoder::Payload(f.bytes);
      if (f.kind == drivers::xbus::kError && !payload.empty()) {
        j["error_code"] = payload[0];
        j["error"] = drivers::xbus::ErrorMeaning(payload[0]);
        text += fmt::format("  error 0x{:02X}: {}", payload[0],
                            drivers::xbus::ErrorMeaning(payload[0]));
      } else if (f.kind == drivers::xbus::kMtData2) {
        nlohmann::json items = nlohmann::json::object();
        drivers::xbus::ForEachItem(payload, [&](const drivers::xbus::Item& item) {
          std::vector<drivers::xbus::NamedValue> values;
          const char* name = drivers::xbus::ItemName(item.type());
          const std::string key = name ? name : fmt::format("0x{:04X}", item.xdi);
          if (!drivers::xbus::ItemValues(item, &values)) {
            items[key] = nullptr;
            return;
          }
          nlohmann::json v = nlohmann::json::object();
          for (const auto& nv : values) v[*nv.name ? nv.name : "value"] = nv.value;
          items[key] = v;
          text += " " + key;
        });
        j["items"] = items;
      }
    }
    Print(j, text);
  }

  void OnSample(const Sample& s) override {
    nlohmann::json j = {{"class", "SAMPLE"}, {"protocol", drivers::ToString(protocol_)}};
    std::string text = "SAMPLE";
    if (s.t_device_s) {
      j["t_device"] = *s.t_device_s;
      text += fmt::format(" t {:.6f}", *s.t_device_s);
    }
    if (s.counter) {
      j["counter"] = *s.counter;
      text += fmt::format(" n {}", *s.counter);
    }
    auto vec = [&](const char* key, const std::optional<Eigen::Vector3d>& v) {
      if (!v) return;
      j[key] = {v->x(), v->y(), v->z()};
      text += fmt::format(" {} [{:+.6f} {:+.6f} {:+.6f}]", key, v->x(), v->y(), v->z());
    };
    vec("acc", s.acc_mps2);
    vec("gyr", s.gyr_radps);
    vec("mag", s.mag);
    if (s.temp_c) {
      j["temp"] = *s.temp_c;
      text += fmt::format(" temp {:.2f}", *s.temp_c);
    }
    j["flags"] = FlagNames(s.flags);
    for (const auto& f : FlagNames(s.flags)) text += " " + f;
    if (s.frame != VectorFrame::kUnknown) {
      j["frame"] = ToString(s.frame);
      text += std::string(" frame ") + ToString(s.frame);
    }
    Print(j, text);
  }

 private:
  void Print(const nlohmann::json& j, const std::string& text) {
    if (json_) {
      std::fputs(j.dump().c_str(), stdout);
    } else {
      std::fputs(text.c_str(), stdout);
    }
    std::fputc('\n', stdout);
  }
  drivers::Protocol protocol_;
  bool json_;
};

bool ParseHex(const std::string& text, std::uint32_t* out) {
  try {
    std::size_t used = 0;
    const unsigned long v = std::stoul(text, &used, 0);
    if (used != text.size() || v > 0xFFFFFFFFul) return false;
    *out = static_cast<std::uint32_t>(v);
    return true;
  } catch (const std::exception&) {
    return false;
  }
}

bool MakeOptions(const DecodeArgs& args, drivers::DecoderOptions* options) {
  options->gx2.timer_ticks_per_s = args.gx2_ticks_per_s;
  options->gx2.little_endian_floats = args.gx2_little_endian;
  std::uint32_t mode = 0x0002, settings = 0x00000001;
  if ((!args.legacy_mode.empty() && (!ParseHex(args.legacy_mode, &mode) || mode > 0xFFFF)) ||
      (!args.legacy_settings.empty() && !ParseHex(args.legacy_settings, &settings))) {
    fmt::print(stderr,
               "turncal decode: --output-mode and --output-settings take numbers (0x...)\n");
    return false;
  }
  options->xbus_legacy.output_mode = static_cast<std::uint16_t>(mode);
  options->xbus_legacy.output_settings = settings;
  return true;
}

void PrintSummary(const drivers::Decoder& decoder, const std::string& device, bool json) {
  const drivers::DecoderCounters& c = decoder.counters();
  if (json) {
    fmt::print("{}\n", nlohmann::json{{"class", "SUMMARY"},
                                      {"device", device},
                                      {"protocol", drivers::ToString(decoder.protocol())},
                                      {"bytes", c.bytes_in},
                                      {"frames", c.frames},
                                      {"samples", c.samples},
                                      {"bad_checksums", c.bad_checksums},
                                      {"bad_structure", c.bad_structure},
                                      {"skipped_bytes", c.bytes_skipped},
                                      {"timeouts", c.timeouts},
                                      {"lost_samples", c.lost_samples},
                                      {"unknown_fields", c.unknown_fields}}
                           .dump());
  } else {
    fmt::print(
        "SUMMARY {}{} bytes: {} frames, {} samples, {} bad checksums, {} malformed, {} bytes "
        "skipped, {} lost samples (counter gaps), {} unknown fields\n",
        device.empty() ? "" : device + ": ", c.bytes_in, c.frames, c.samples, c.bad_checksums,
        c.bad_structure, c.bytes_skipped, c.lost_samples, c.unknown_fields);
  }
}

// A .tcap capture: one decoder per device of the header, events printed as they come.
int RunCapture(const DecodeArgs& args, const drivers::DecoderOptions& base) {
  drivers::CaptureReader reader;
  std::string error;
  if (!reader.Open(args.file, &error)) {
    fmt::print(stderr, "turncal decode: {}\n", error);
    return 2;
  }
  std::optional<drivers::Protocol> forced;
  if (!args.protocol.empty()) forced = drivers::ParseProtocol(args.protocol);
  std::vector<std::unique_ptr<PrintingSink>> sinks;
  std::vector<std::unique_ptr<drivers::Decoder>> decoders;
  for (const auto& d : reader.header().devices) {
    const drivers::Protocol p = forced.value_or(d.protocol);
    drivers::DecoderOptions options = base;
    options.device = d.name;
    if (d.output_mode && args.legacy_mode.empty()) options.xbus_legacy.output_mode = *d.output_mode;
    if (d.output_settings && args.legacy_settings.empty()) {
      options.xbus_legacy.output_settings = *d.output_settings;
    }
    sinks.push_back(std::make_unique<PrintingSink>(p, args.json));
    decoders.push_back(drivers::MakeDecoder(p, options, sinks.back().get(), &error));
    if (!decoders.back()) {
      fmt::print(stderr, "turncal decode: device '{}': {}\n", d.name, error);
      return 2;
    }
  }
  drivers::CaptureRecord r;
  std::uint64_t events = 0, sent = 0;
  while (reader.Next(&r)) {
    if (r.type == drivers::RecordType::kEvent) {
      ++events;
      const std::string text(r.payload.begin(), r.payload.end());
      auto j = nlohmann::json::parse(text, nullptr, false);
      if (args.json) {
        fmt::print("{}\n", nlohmann::json{{"class", "EVENT"},
                                          {"t_ns", r.t_ns},
                                          {"event", j.is_discarded() ? nlohmann::json(text) : j}}
                               .dump());
      } else {
        fmt::print("EVENT  t {:.6f} s  {}\n", r.t_ns * 1e-9, text);
      }
      continue;
    }
    if (r.device >= decoders.size()) {
      fmt::print(stderr, "turncal decode: a record names device {} of {}; skipped\n", r.device,
                 decoders.size());
      continue;
    }
    if (r.type == drivers::RecordType::kSent) {
      ++sent;
      continue;
    }
    decoders[r.device]->Push(r.payload, static_cast<std::int64_t>(r.t_ns));
  }
  if (!reader.error().empty()) fmt::print(stderr, "turncal decode: {}\n", reader.error());
  if (reader.truncated()) {
    fmt::print(stderr, "turncal decode: the capture ends inside a record ({} bytes ignored)\n",
               reader.trailing_bytes());
  }
  for (std::size_t i = 0; i < decoders.size(); ++i) {
    decoders[i]->Finish();
    PrintSummary(*decoders[i], reader.header().devices[i].name, args.json);
  }
  if (!args.json) fmt::print("{} events, {} sent records\n", events, sent);
  return reader.error().empty() ? 0 : 1;
}

// The codes RunDecode returns.
constexpr Manual kDecodeManual = {
    "Decodes a capture or a raw byte stream: frames and samples (SI units), then one SUMMARY "
    "line with the counters (frames, samples, bad checksums, skipped bytes).",
    "turncal decode session.tcap | tail -1\n"
    "turncal decode stream.bin --protocol mip --json | head",
    "0 decoded (bad frames are counted, not fatal); 2 the input cannot be read or a "
    "command-line mistake",
    "docs/DRIVERS.md, docs/TROUBLESHOOTING.md (baud rate)"};

int RunDecode(const DecodeArgs& args) {
  drivers::DecoderOptions options;
  if (!MakeOptions(args, &options)) return 2;
  const std::optional<bool> is_capture = drivers::FileLooksLikeCapture(args.file);
  if (!is_capture) {
    fmt::print(stderr, "turncal decode: cannot open '{}'\n", args.file);
    return 2;
  }
  const bool capture = *is_capture;
  if (!args.protocol.empty() && !drivers::ParseProtocol(args.protocol)) {
    fmt::print(stderr, "turncal decode: unknown protocol '{}' (mip, gx2, xbus, xbus-legacy)\n",
               args.protocol);
    return 2;
  }
  if (capture) return RunCapture(args, options);
  if (args.protocol.empty()) {
    fmt::print(stderr, "turncal decode: '{}' is a raw stream: name its --protocol\n", args.file);
    return 2;
  }
  std::ifstream in(args.file, std::ios::binary);
  const drivers::Protocol protocol = *drivers::ParseProtocol(args.protocol);
  PrintingSink sink(protocol, args.json);
  std::string error;
  auto decoder = drivers::MakeDecoder(protocol, options, &sink, &error);
  if (!decoder) {
    fmt::print(stderr, "turncal decode: {}\n", error);
    return 2;
  }
  drivers::DecodeStream(in, decoder.get(), args.chunk);
  PrintSummary(*decoder, "", args.json);
  return 0;
}

}  // namespace

void AddDecodeCommand(CLI::App* app) {
  auto args = std::make_shared<DecodeArgs>();
  auto* cmd = app->add_subcommand(
      "decode", "decode a raw byte stream: frames and samples, then a summary of the counters");
  SetManual(cmd, kDecodeManual);
  cmd->add_option("file", args->file, "a .tcap capture, or a raw byte stream (.bin)")->required();
  cmd->add_option("--protocol", args->protocol,
                  "mip | gx2 | xbus | xbus-legacy (required for a raw stream; overrides a "
                  "capture's header)");
  cmd->add_flag("--json", args->json, "one JSON object a line");
  cmd->add_option("--gx2-timer-rate", args->gx2_ticks_per_s,
                  "GX2 timer ticks per second (GX2 19660800, GX3-25 62500)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_flag("--gx2-little-endian", args->gx2_little_endian,
                "GX3-25 with little-endian floats (0xDB flags bit 4)");
  cmd->add_option("--output-mode", args->legacy_mode,
                  "xbus-legacy OutputMode (default: the capture header's, else 0x0002)");
  cmd->add_option("--output-settings", args->legacy_settings,
                  "xbus-legacy OutputSettings (default: the capture header's, else 0x00000001)");
  cmd->add_option("--chunk", args->chunk, "bytes read and pushed at a time")
      ->check(CLI::Range(1, 1 << 24))
      ->capture_default_str();
  cmd->callback([args] { throw CLI::RuntimeError(RunDecode(*args)); });
}

}  // namespace turncal::tools
