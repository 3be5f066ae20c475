// Decoder throughput (issue "Device drivers"; docs/PERFORMANCE.md): the full path from bytes to
// Samples (scan, checksums, fields, grouping, counters) fed in 512-byte chunks, and the heap
// allocations per frame in the steady state (global operator new counted).
// Run: TURNCAL_SHARED_DIR=../shared build/tests/decoder_bench
#include <benchmark/benchmark.h>

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <new>

#include "drivers/gx2/gx2_decoder.h"
#include "drivers/gx2/gx2_encoder.h"
#include "drivers/mip/mip_decoder.h"
#include "drivers/mip/mip_encoder.h"
#include "drivers/xbus/xbus_decoder.h"
#include "drivers/xbus/xbus_encoder.h"

namespace {
std::atomic<std::uint64_t> g_allocations{0};
}  // namespace

void* operator new(std::size_t size) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(size)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

namespace turncal::drivers {
namespace {

class CountingSink : public DecoderSink {
 public:
  void OnFrame(const FrameView& f) override { bytes += f.bytes.size(); }
  void OnSample(const Sample& s) override {
    ++samples;
    if (s.acc_mps2) sum += s.acc_mps2->x();
  }
  std::uint64_t bytes = 0, samples = 0;
  double sum = 0;
};

std::vector<std::uint8_t> ReadFixture(const char* relative) {
  const char* shared = std::getenv("TURNCAL_SHARED_DIR");
  if (!shared) return {};
  std::ifstream in(std::filesystem::path(shared) / "fixtures" / relative, std::ios::binary);
  return std::vector<std::uint8_t>((std::istreambuf_iterator<char>(in)),
                                   std::istreambuf_iterator<char>());
}

Sample Numbered(int i) {
  Sample s;
  s.t_device_s = 100.0 + i * 0.002;
  s.counter = static_cast<std::uint32_t>(i & 0xFFFF);
  s.acc_mps2 = Eigen::Vector3d(0.01, -9.80665, 0.02 * (i % 3));
  s.gyr_radps = Eigen::Vector3d(1e-3, -2e-3, 3e-3);
  s.mag = Eigen::Vector3d(0.25, 0.02, 0.40);
  return s;
}

template <class D, class... Extra>
void Feed(benchmark::State& state, const std::vector<std::uint8_t>& data, Extra... extra) {
  if (data.empty()) {
    state.SkipWithError("no data (set TURNCAL_SHARED_DIR for the fixture benchmarks)");
    return;
  }
  CountingSink sink;
  D decoder("imu", &sink, extra...);
  constexpr std::size_t kChunk = 512;
  std::uint64_t allocations = 0, frames = 0;
  for (auto _ : state) {
    const std::uint64_t before_alloc = g_allocations.load(std::memory_order_relaxed);
    const std::uint64_t before_frames = decoder.counters().frames;
    for (std::size_t at = 0; at < data.size(); at += kChunk) {
      decoder.Push(
          std::span<const std::uint8_t>(data.data() + at, std::min(kChunk, data.size() - at)), 0);
    }
    allocations += g_allocations.load(std::memory_order_relaxed) - before_alloc;
    frames += decoder.counters().frames - before_frames;
  }
  benchmark::DoNotOptimize(sink.sum);
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations() * data.size()));
  state.counters["frames"] = static_cast<double>(frames) / static_cast<double>(state.iterations());
  state.counters["allocs_per_frame"] = frames ? static_cast<double>(allocations) / frames : 0.0;
  state.counters["bad_checksums"] = static_cast<double>(decoder.counters().bad_checksums);
}

void BM_MipFixture(benchmark::State& state) {
  static const auto data = ReadFixture("microstrain/mip_sdk/mip_data.bin");
  Feed<MipDecoder>(state, data);
}
BENCHMARK(BM_MipFixture);

void BM_XbusEinride1(benchmark::State& state) {
  static const auto data = ReadFixture("xsens/einride-1/output.bin");
  Feed<XbusDecoder>(state, data);
}
BENCHMARK(BM_XbusEinride1);

// Synthetic streams (no fixtures needed): 20000 frames of each protocol's sample frame.
void BM_MipSynthetic(benchmark::State& state) {
  static const auto data = [] {
    std::vector<std::uint8_t> out;
    for (int i = 0; i < 20000; ++i) {
      const auto f = mip::SensorPacket(Numbered(i));
      out.insert(out.end(), f.begin(), f.end());
    }
    return out;
  }();
  Feed<MipDecoder>(state, data);
}
BENCHMARK(BM_MipSynthetic);

void BM_XbusMtData2Synthetic(benchmark::State& state) {
  static const auto data = [] {
    std::vector<std::uint8_t> out;
    for (int i = 0; i < 20000; ++i) {
      const auto f = xbus::MtData2(Numbered(i));
      out.insert(out.end(), f.begin(), f.end());
    }
    return out;
  }();
  Feed<XbusDecoder>(state, data);
}
BENCHMARK(BM_XbusMtData2Synthetic);

void BM_Gx2Synthetic(benchmark::State& state) {
  static const auto data = [] {
    std::vector<std::uint8_t> out;
    for (int i = 0; i < 20000; ++i) {
      const auto f = gx2::Reply(0xCB, Numbered(i), {});
      out.insert(out.end(), f.begin(), f.end());
    }
    return out;
  }();
  Feed<Gx2Decoder>(state, data);
}
BENCHMARK(BM_Gx2Synthetic);

}  // namespace
}  // namespace turncal::drivers

BENCHMARK_MAIN();
