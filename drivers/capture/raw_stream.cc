#include "drivers/capture/raw_stream.h"

#include <fmt/format.h>

#include <cmath>
#include <fstream>

#include "drivers/decoder_factory.h"

namespace turncal::drivers {
namespace {

class Collect : public DecoderSink {
 public:
  explicit Collect(std::vector<Sample>* out) : out_(out) {}
  void OnFrame(const FrameView&) override {}
  void OnSample(const Sample& s) override { out_->push_back(s); }

 private:
  std::vector<Sample>* out_;
};

}  // namespace

bool ReadRawStream(const std::string& path, Protocol protocol, double rate_hz,
                   std::vector<Sample>* out, RawStreamStats* stats, std::string* error) {
  out->clear();
  *stats = RawStreamStats{};
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    *error = fmt::format("cannot open '{}'", path);
    return false;
  }
  Collect sink(out);
  auto decoder = MakeDecoder(protocol, DecoderOptions{}, &sink, error);
  if (!decoder) return false;
  DecodeStream(in, decoder.get());
  stats->decoder = decoder->counters();
  if (out->empty()) return true;
  const bool clocked = out->front().t_device_s.has_value();
  if (!clocked && !(rate_hz > 0)) {
    *error = "the stream's samples carry no time: give their rate (samples per second)";
    return false;
  }
  stats->device_clock = clocked;
  const double t0 = clocked ? *out->front().t_device_s : 0.0;
  for (std::size_t i = 0; i < out->size(); ++i) {
    Sample& s = (*out)[i];
    const double t =
        s.t_device_s && clocked ? *s.t_device_s - t0 : static_cast<double>(i) / rate_hz;
    s.t_host_ns = static_cast<std::int64_t>(std::llround(t * 1e9));
  }
  return true;
}

std::int64_t DropHeldRepeats(std::vector<Sample>* samples) {
  auto only_mag = [](const Sample& s) { return s.mag && !s.acc_mps2 && !s.gyr_radps; };
  std::int64_t repeats = 0, n = 0;
  for (std::size_t i = 1; i < samples->size(); ++i) {
    const Sample &a = (*samples)[i - 1], &b = (*samples)[i];
    if (!only_mag(a) || !only_mag(b)) return 0;
    ++n;
    repeats += *a.mag == *b.mag;
  }
  if (n == 0 || 3 * repeats <= n) return 0;
  std::vector<Sample> kept;
  kept.reserve(samples->size() - static_cast<std::size_t>(repeats));
  for (std::size_t i = 0; i < samples->size(); ++i) {
    if (i == 0 || *(*samples)[i].mag != *(*samples)[i - 1].mag) kept.push_back((*samples)[i]);
  }
  const auto dropped = static_cast<std::int64_t>(samples->size() - kept.size());
  *samples = std::move(kept);
  return dropped;
}

}  // namespace turncal::drivers
