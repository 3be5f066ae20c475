// The sequencer's cost per sample (stillness window, outlier gate, Welford records) on a still
// stream with one pose collecting, at 100 Hz and 1000 Hz (window 50 and 500 samples).
// Run: build/tests/sequencer_bench
#include <benchmark/benchmark.h>

#include <random>

#include "core/sequencing/sequencer.h"

namespace turncal {
namespace {

void BM_SequencerPush(benchmark::State& state) {
  const double rate = static_cast<double>(state.range(0));
  SequencerOptions o;
  o.dwell_s = 1e6;  // one pose that never completes: every sample is committed
  Sequencer seq(o, [](const SequencerEvent&) {});
  std::mt19937_64 rng(1);
  std::normal_distribution<double> n(0, 1);
  std::vector<Sample> samples(4096);
  for (auto& s : samples) {
    s.acc_mps2 = Eigen::Vector3d(0.01 * n(rng), 0.01 * n(rng), -9.8 + 0.01 * n(rng));
    s.gyr_radps = Eigen::Vector3d(1e-3 * n(rng), 1e-3 * n(rng), 1e-3 * n(rng));
    s.mag = Eigen::Vector3d(0.2 + 1e-3 * n(rng), 1e-3 * n(rng), 0.4 + 1e-3 * n(rng));
  }
  std::int64_t k = 0;
  auto push = [&] {
    Sample s = samples[static_cast<std::size_t>(k) % samples.size()];
    s.t_host_ns = static_cast<std::int64_t>(static_cast<double>(k) / rate * 1e9);
    s.t_device_s = static_cast<double>(k) / rate;
    s.counter = static_cast<std::uint32_t>(k);
    seq.Push(s);
    ++k;
  };
  // Noise measured, pose announced and collecting before timing starts.
  for (int i = 0; i < static_cast<int>(2 * rate); ++i) push();
  Announcement a;
  a.t_host_ns = static_cast<std::int64_t>(static_cast<double>(k) / rate * 1e9);
  std::string error;
  seq.Announce(a, &error);
  for (int i = 0; i < static_cast<int>(2 * rate); ++i) push();
  for (auto _ : state) push();
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_SequencerPush)->Arg(100)->Arg(1000);

}  // namespace
}  // namespace turncal

BENCHMARK_MAIN();
