// The streaming Allan and Hadamard sums per sample (core/analysis/streaming_allan.h): the cost of
// `turncal noise` beyond reading its input. items_per_second is samples (of every channel) a
// second; the per-sample cost does not depend on the recording's length (the sizes below).
#include <benchmark/benchmark.h>

#include <random>
#include <vector>

#include "core/analysis/streaming_allan.h"

namespace {

void BM_StreamingAllan(benchmark::State& state) {
  const int channels = static_cast<int>(state.range(0));
  const std::int64_t samples = state.range(1);
  std::mt19937_64 rng(1);
  std::normal_distribution<double> normal;
  std::vector<double> noise(4096 * static_cast<std::size_t>(channels));
  for (double& v : noise) v = normal(rng);
  for (auto _ : state) {
    turncal::StreamingAllan allan(channels);
    for (std::int64_t i = 0; i < samples; ++i) {
      allan.Add(noise.data() + static_cast<std::size_t>((i & 4095) * channels));
    }
    benchmark::DoNotOptimize(allan.Points());
  }
  state.SetItemsProcessed(state.iterations() * samples);
  turncal::StreamingAllan probe(channels);
  for (std::int64_t i = 0; i < samples; ++i) {
    probe.Add(noise.data() + static_cast<std::size_t>((i & 4095) * channels));
  }
  state.counters["memory_kB"] = static_cast<double>(probe.MemoryBytes()) / 1024.0;
}
BENCHMARK(BM_StreamingAllan)
    ->Args({3, 1 << 20})
    ->Args({6, 1 << 20})
    ->Args({6, 1 << 23})
    ->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
