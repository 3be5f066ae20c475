// Speed of the observability analysis and the next-pose planner, which the daemon runs after
// every pose (docs/PERFORMANCE.md). Run: build/tests/observability_bench
#include <benchmark/benchmark.h>

#include "core/observability.h"
#include "core/pose_planner.h"
#include "core/synthetic.h"

namespace turncal {
namespace {

std::vector<WeightedPose> Poses(const MeasurementModel& model, int n, std::mt19937_64* rng) {
  const CalibratorOptions o = OptionsForClass(model, IndustrialClass());
  const Eigen::Matrix3d W = ExpectedSqrtInformation(o.noise_density, o.pose_offset_sigma, 5.0);
  std::vector<WeightedPose> out;
  for (const auto& p : RandomPoses(n, rng)) out.push_back({p, Eigen::Vector3d::Zero(), W});
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
// tolerances, so that the greedy continuation runs for a dozen poses).
void BM_PlanNextPose(benchmark::State& state) {
  std::string error;
  auto accel = MakeModel("accel13", ModelContext{}, &error);
  auto mag = MakeModel("mag13", ModelContext{}, &error);
  std::mt19937_64 rng(2);
  std::vector<PlanningTarget> targets(2);
  const MeasurementModel* models[2] = {accel.get(), mag.get()};
  for (int i = 0; i < 2; ++i) {
    targets[i].model = models[i];
    targets[i].theta = DrawTruth(*models[i], IndustrialClass(), &rng);
    targets[i].captured = Poses(*models[i], static_cast<int>(state.range(0)), &rng);
    GateTolerancesForClass("consumer", &targets[i].gate.tolerances);
    const CalibratorOptions o = OptionsForClass(*models[i], IndustrialClass());
    targets[i].sqrt_information =
        ExpectedSqrtInformation(o.noise_density, o.pose_offset_sigma, 5.0);
  }
  PlannerOptions options;
  options.horizon = static_cast<int>(state.range(1));
  for (auto _ : state) benchmark::DoNotOptimize(PlanNextPose(targets, options));
}
BENCHMARK(BM_PlanNextPose)->Args({26, 1})->Args({0, 60})->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace turncal

BENCHMARK_MAIN();
