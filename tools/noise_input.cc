#include "tools/noise_input.h"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <sstream>

#include "daemon/station/capture_replay.h"
#include "drivers/capture/tcap.h"
#include "drivers/decoder_factory.h"

namespace turncal::tools {

namespace {

double SampleTime(const Sample& s) {
  return s.t_device_s ? *s.t_device_s : static_cast<double>(s.t_host_ns) * 1e-9;
}

// The progress line: every second at most, on a terminal rewritten in place.
class Progress {
 public:
  Progress(const std::string& mode, std::uint64_t total, std::function<std::uint64_t()> where)
      : total_(total), where_(std::move(where)), start_(Clock::now()), last_(start_) {
    terminal_ = isatty(STDERR_FILENO) != 0;
    on_ = total_ > 0 && (mode == "always" || (mode == "auto" && terminal_));
  }
  void Tick() {
    if (!on_ || (++ticks_ & 0x3FFF) != 0) return;
    const auto now = Clock::now();
    if (now - last_ < std::chrono::seconds(1)) return;
    last_ = now;
    Print(now, false);
  }
  void Done() {
    if (on_) Print(Clock::now(), true);
  }

 private:
  using Clock = std::chrono::steady_clock;
  void Print(Clock::time_point now, bool done) {
    const double elapsed = std::chrono::duration<double>(now - start_).count();
    const double at = static_cast<double>(done ? total_ : std::min(where_(), total_));
    const double fraction = at / static_cast<double>(total_);
    const std::string eta = done || !(fraction > 0) ? ""
                                                    : fmt::format(", about {:.0f} s left",
                                                                  elapsed / fraction - elapsed);
    fmt::print(stderr, "{}turncal noise: {:3.0f} % of {:.1f} MB in {:.1f} s{}{}",
               terminal_ ? "\r" : "", 100 * fraction, static_cast<double>(total_) / 1e6, elapsed,
               eta, terminal_ && !done ? "   " : "\n");
    std::fflush(stderr);
  }

  std::uint64_t total_;
  std::function<std::uint64_t()> where_;
  Clock::time_point start_, last_;
  bool terminal_ = false, on_ = false;
  std::uint64_t ticks_ = 0;
};

bool Wanted(const NoiseInputArgs& args, const char* triad) {
  return args.text_triads.empty() || std::find(args.text_triads.begin(), args.text_triads.end(),
                                               triad) != args.text_triads.end();
}

void AddSample(const Sample& s, double t, const NoiseInputArgs& args, NoiseInput* out) {
  if (s.acc_mps2 && Wanted(args, "acc")) out->noise.acc.Add(t, *s.acc_mps2, args.from_s, args.to_s);
  if (s.gyr_radps && Wanted(args, "gyr"))
    out->noise.gyr.Add(t, *s.gyr_radps, args.from_s, args.to_s);
  if (s.mag && Wanted(args, "mag")) out->noise.mag.Add(t, *s.mag, args.from_s, args.to_s);
}

class Collector : public daemon::ReplayTarget, public drivers::DecoderSink {
 public:
  Collector(int device, const NoiseInputArgs& args, NoiseInput* out, Progress* progress)
      : device_(device), args_(args), out_(out), progress_(progress) {}
  void OnSample(int device, const Sample& s) override {
    if (device == device_) OnSample(s);
  }
  bool OnAnnounce(const Announcement&, const std::vector<int>&, std::string*) override {
    return true;
  }
  void OnTick(std::int64_t) override {}
  void OnFinish(std::int64_t) override {}
  void OnFrame(const drivers::FrameView&) override {}
  void OnSample(const Sample& s) override {
    AddSample(s, SampleTime(s), args_, out_);
    progress_->Tick();
  }

 private:
  int device_;
  const NoiseInputArgs& args_;
  NoiseInput* out_;
  Progress* progress_;
};

std::uint64_t FileSize(const std::string& path) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  return in ? static_cast<std::uint64_t>(std::max<std::streamoff>(in.tellg(), 0)) : 0;
}

// Text columns: time in seconds, then x y z of each triad in --triad's order (imu_tk's .mat
// text files, CSV exports); lines that do not parse (headers, comments) are skipped and counted.
int ReadText(const NoiseInputArgs& args, NoiseInput* out) {
  std::ifstream in(args.file);
  if (!in) {
    fmt::print(stderr, "turncal noise: cannot open '{}'\n", args.file);
    return 2;
  }
  Progress progress(args.progress, FileSize(args.file), [&in] {
    return static_cast<std::uint64_t>(std::max<std::streamoff>(in.tellg(), 0));
  });
  const std::vector<std::string> triads =
      args.text_triads.empty() ? std::vector<std::string>{"acc"} : args.text_triads;
  std::string line;
  std::vector<double> v(1 + 3 * triads.size());
  while (std::getline(in, line)) {
    out->bytes += line.size() + 1;
    // strtod over the line: commas, tabs and spaces all separate.
    const char* p = line.c_str();
    bool ok = true;
    for (double& x : v) {
      while (*p == ' ' || *p == ',' || *p == '\t' || *p == ';') ++p;
      char* end = nullptr;
      x = std::strtod(p, &end);
      if (end == p || !std::isfinite(x)) {
        ok = false;
        break;
      }
      p = end;
    }
    if (!ok) {
      ++out->skipped;
      continue;
    }
    Sample s;
    for (std::size_t k = 0; k < triads.size(); ++k) {
      const Eigen::Vector3d value =
          args.text_scale * Eigen::Vector3d(v[1 + 3 * k], v[2 + 3 * k], v[3 + 3 * k]);
      if (triads[k] == "gyr") {
        s.gyr_radps = value;
      } else if (triads[k] == "mag") {
        s.mag = value;
      } else {
        s.acc_mps2 = value;
      }
    }
    AddSample(s, v[0], args, out);
    progress.Tick();
  }
  progress.Done();
  return 0;
}

// A NumPy .npy file (format 1.0-3.0): a C-order float64 or float32 array of shape (n, 1 + 3k),
// its columns as the text columns'. Read a MiB at a time.
int ReadNpy(const NoiseInputArgs& args, NoiseInput* out) {
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> file(std::fopen(args.file.c_str(), "rb"),
                                                       &std::fclose);
  auto fail = [&](const std::string& why) {
    fmt::print(stderr, "turncal noise: {}: {}\n", args.file, why);
    return 2;
  };
  if (!file) return fail("cannot open");
  unsigned char magic[10];
  if (std::fread(magic, 1, 10, file.get()) != 10 || std::memcmp(magic, "\x93NUMPY", 6) != 0) {
    return fail("not a .npy file");
  }
  std::size_t header_length = magic[8] | (magic[9] << 8);
  if (magic[6] >= 2) {
    unsigned char more[2];
    if (std::fread(more, 1, 2, file.get()) != 2) return fail("a truncated .npy header");
    header_length |=
        (static_cast<std::size_t>(more[0]) << 16) | (static_cast<std::size_t>(more[1]) << 24);
  }
  if (header_length > (1u << 20)) return fail("a .npy header of over a MiB");
  std::string header(header_length, '\0');
  if (std::fread(header.data(), 1, header_length, file.get()) != header_length) {
    return fail("a truncated .npy header");
  }
  const bool f8 = header.find("'<f8'") != std::string::npos;
  const bool f4 = header.find("'<f4'") != std::string::npos;
  if (!f8 && !f4) return fail("only little-endian float64 or float32 arrays (descr <f8, <f4)");
  if (header.find("'fortran_order': True") != std::string::npos) {
    return fail("a Fortran-order array: save it with np.ascontiguousarray");
  }
  const auto shape_at = header.find("'shape': (");
  long rows = 0, columns = 0;
  if (shape_at == std::string::npos ||
      std::sscanf(header.c_str() + shape_at, "'shape': (%ld, %ld)", &rows, &columns) != 2) {
    return fail("the array must have two dimensions (samples x columns)");
  }
  const std::vector<std::string> triads =
      args.text_triads.empty() ? std::vector<std::string>{"acc"} : args.text_triads;
  if (columns != static_cast<long>(1 + 3 * triads.size())) {
    return fail(fmt::format("{} columns, and --triad asks for {} (time, then x y z of each)",
                            columns, 1 + 3 * triads.size()));
  }
  const std::size_t width = f8 ? 8 : 4, row_bytes = width * static_cast<std::size_t>(columns);
  const std::uint64_t total = row_bytes * static_cast<std::uint64_t>(rows);
  std::uint64_t read = 0;
  Progress progress(args.progress, total, [&read] { return read; });
  std::vector<unsigned char> chunk(row_bytes * 16384);
  std::vector<double> v(static_cast<std::size_t>(columns));
  for (long row = 0; row < rows;) {
    const std::size_t want = static_cast<std::size_t>(std::min<long>(16384, rows - row));
    const std::size_t got = std::fread(chunk.data(), row_bytes, want, file.get());
    for (std::size_t r = 0; r < got; ++r) {
      const unsigned char* p = chunk.data() + r * row_bytes;
      for (std::size_t c = 0; c < v.size(); ++c) {
        if (f8) {
          std::memcpy(&v[c], p + 8 * c, 8);
        } else {
          float f;
          std::memcpy(&f, p + 4 * c, 4);
          v[c] = f;
        }
      }
      Sample s;
      for (std::size_t k = 0; k < triads.size(); ++k) {
        const Eigen::Vector3d value =
            args.text_scale * Eigen::Vector3d(v[1 + 3 * k], v[2 + 3 * k], v[3 + 3 * k]);
        (triads[k] == "gyr" ? s.gyr_radps : triads[k] == "mag" ? s.mag : s.acc_mps2) = value;
      }
      AddSample(s, v[0], args, out);
      progress.Tick();
    }
    read += got * row_bytes;
    row += static_cast<long>(got);
    if (got < want) {
      progress.Done();
      out->bytes = read;
      return fail(fmt::format("ends after {} of its {} rows", row, rows));
    }
  }
  progress.Done();
  out->bytes = read;
  return 0;
}

// A capture's device (--device, or the first).
int ReadCapture(const NoiseInputArgs& args, NoiseInput* out) {
  std::string error;
  drivers::CaptureReader reader;
  if (!reader.Open(args.file, &error)) {
    fmt::print(stderr, "turncal noise: {}\n", error);
    return 2;
  }
  int device = 0;
  if (!args.device.empty()) {
    device = -1;
    for (std::size_t i = 0; i < reader.header().devices.size(); ++i)
      if (reader.header().devices[i].name == args.device) device = static_cast<int>(i);
    if (device < 0) {
      fmt::print(stderr, "turncal noise: the capture has no device '{}'\n", args.device);
      return 2;
    }
  }
  out->source = reader.header().devices.empty()
                    ? ""
                    : reader.header().devices[static_cast<std::size_t>(device)].name;
  Progress progress(args.progress, reader.size(), [&reader] { return reader.position(); });
  Collector collector(device, args, out, &progress);
  daemon::ReplayStats stats;
  if (!daemon::ReplayInto(&reader, &collector, false, {}, &stats, &error)) {
    fmt::print(stderr, "turncal noise: {}\n", error);
    return 2;
  }
  progress.Done();
  out->bytes = reader.position();
  return 0;
}

// A raw device stream in --protocol.
int ReadRaw(const NoiseInputArgs& args, NoiseInput* out) {
  std::string error;
  const auto protocol = drivers::ParseProtocol(args.protocol);
  if (!protocol) {
    fmt::print(stderr, "turncal noise: unknown protocol '{}'\n", args.protocol);
    return 2;
  }
  std::ifstream in(args.file, std::ios::binary);
  if (!in) {
    fmt::print(stderr, "turncal noise: cannot open '{}'\n", args.file);
    return 2;
  }
  std::uint64_t read = 0;
  Progress progress(args.progress, FileSize(args.file), [&read] { return read; });
  Collector collector(0, args, out, &progress);
  auto decoder = drivers::MakeDecoder(*protocol, drivers::DecoderOptions{}, &collector, &error);
  if (!decoder) {
    fmt::print(stderr, "turncal noise: {}\n", error);
    return 2;
  }
  std::vector<char> buffer(1 << 16);
  while (in) {
    in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
    const auto n = static_cast<std::size_t>(in.gcount());
    if (n == 0) break;
    read += n;
    decoder->Push(
        std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(buffer.data()), n), 0);
  }
  decoder->Finish();
  progress.Done();
  out->bytes = read;
  return 0;
}

}  // namespace

int ReadNoiseInput(const NoiseInputArgs& args, NoiseInput* out) {
  const auto start = std::chrono::steady_clock::now();
  const std::optional<bool> is_capture = drivers::FileLooksLikeCapture(args.file);
  if (!is_capture) {
    fmt::print(stderr, "turncal noise: cannot open '{}'\n", args.file);
    return 2;
  }
  const bool npy = args.file.size() > 4 && args.file.compare(args.file.size() - 4, 4, ".npy") == 0;
  const int code = *is_capture              ? ReadCapture(args, out)
                   : !args.protocol.empty() ? ReadRaw(args, out)
                   : npy                    ? ReadNpy(args, out)
                                            : ReadText(args, out);
  out->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return code;
}

}  // namespace turncal::tools
