// Speed of the observability analysis and the next-pose planner, which the daemon runs after
// every pose (docs/PERFORMANCE.md). Run: build/tests/observability_bench
#include <benchmark/benchmark.h>

#include "core/analysis/observability.h"
#include "core/planning/pose_planner.h"
#include "sim/synthetic.h"

namespace turncal {
namespace {

std::vector<WeightedPose> Poses(const MeasurementModel& model, int n, std::mt19937_64* rng) {
  const CalibratorOptions o = OptionsForClass(model, IndustrialClass());
  const Eigen::Matrix3d W = ExpectedSqrtInformation(o.noise_density, o.pose_offset_sigma, 5.0);
  std::vector<WeightedPose> out;
  for (const auto& p : RandomPoses(n, rng)) out.push_back({p, Eigen::Vector3d::Zero(), W, nullptr});
  return out;
}

void BM_AnalyzeData(benchmark::State& state, const char* name) {
  std::string error;
  auto model = MakeModel(name, ModelContext{}, &error);
  std::mt19937_64 rng(1);
  const Eigen::VectorXd theta = DrawTruth(*model, IndustrialClass(), &rng);
  const auto poses = Poses(*model, static_cast<int>(state.range(0)), &rng);
  for (auto _ : state) {
    benchmark::DoNotOptimize(AnalyzeData(*model, theta, poses, ObservabilityOptions{}));
  }
}
BENCHMARK_CAPTURE(BM_AnalyzeData, accel13, "accel13")
    ->Arg(26)
    ->Arg(100)
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_AnalyzeData, mag22, "mag22")->Arg(26)->Arg(100)->Unit(benchmark::kMillisecond);

// accel13 + mag13 together, the default 672-pose grid; args: poses captured, horizon (consumer
// tolerances, so that the greedy continuation runs for a dozen poses), and whether the drift
// model is used (1: the class's Gauss-Markov drift, poses 9 s apart; 0: independent poses).
void BM_PlanNextPose(benchmark::State& state) {
  std::string error;
  auto accel = MakeModel("accel13", ModelContext{}, &error);
  auto mag = MakeModel("mag13", ModelContext{}, &error);
  std::mt19937_64 rng(2);
  std::vector<PlanningTarget> targets(2);
  const MeasurementModel* models[2] = {accel.get(), mag.get()};
  const bool drift = state.range(2) != 0;
  for (int i = 0; i < 2; ++i) {
    targets[i].model = models[i];
    targets[i].theta = DrawTruth(*models[i], IndustrialClass(), &rng);
    targets[i].captured = Poses(*models[i], static_cast<int>(state.range(0)), &rng);
    GateDefaultsForClass("consumer", &targets[i].gate);
    const CalibratorOptions o = drift ? DriftOptionsForClass(*models[i], IndustrialClass())
                                      : OptionsForClass(*models[i], IndustrialClass());
    targets[i].sqrt_information =
        ExpectedPoseSqrtInformation(*models[i], IndustrialClass(), o, 5.0, 100.0);
    if (drift) {
      targets[i].drift = o.drift;
      for (std::size_t k = 0; k < targets[i].captured.size(); ++k) {
        targets[i].captured[k].sqrt_information = targets[i].sqrt_information;
        targets[i].captured_windows.push_back({9.0 * k + 4, 9.0 * k + 9});
      }
    }
  }
  PlannerOptions options;
  options.horizon = static_cast<int>(state.range(1));
  for (auto _ : state) benchmark::DoNotOptimize(PlanNextPose(targets, options));
}
BENCHMARK(BM_PlanNextPose)
    ->Args({26, 1, 0})
    ->Args({0, 60, 0})
    ->Args({26, 1, 1})
    ->Args({100, 1, 1})
    ->Args({0, 60, 1})
    ->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace turncal

BENCHMARK_MAIN();
