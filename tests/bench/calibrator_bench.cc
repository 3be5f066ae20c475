// Calibrator speed (issue "Calibration engine"): run on demand, never as a timed test.
//   build/tests/calibrator_bench
// Results and the machine are recorded in docs/PERFORMANCE.md.

#include <benchmark/benchmark.h>

#include <initializer_list>

#include "core/estimation/calibrator.h"
#include "sim/synthetic.h"

namespace turncal {
namespace {

struct Session {
  std::unique_ptr<MeasurementModel> model;
  std::vector<PoseRecord> records;
  CalibratorOptions options;
};

// `drift`: the station's calibrator (bias drift in time, generalised least squares over all
// poses), the records 9 s apart with 5 s windows.
Session MakeSession(const std::string& name, int poses, std::uint64_t seed, bool drift = false) {
  Session s;
  std::string error;
  s.model = MakeModel(name, ModelContext{}, &error);
  const SensorClass sensor = IndustrialClass();
  std::mt19937_64 rng(seed);
  const Eigen::VectorXd truth = DrawTruth(*s.model, sensor, &rng);
  for (const auto& pose : RandomPoses(poses, &rng)) {
    s.records.push_back(SimulateRecord(*s.model, truth, pose, sensor, 5.0, &rng));
  }
  s.options = drift ? DriftOptionsForClass(*s.model, sensor) : OptionsForClass(*s.model, sensor);
  for (std::size_t i = 0; drift && i < s.records.size(); ++i) {
    s.records[i].t_start_s = 9.0 * static_cast<double>(i);
    s.records[i].t_end_s = s.records[i].t_start_s + 5.0;
  }
  return s;
}

// Cold solve: add every pose, linear start, Levenberg-Marquardt, covariance, residuals.
void FullSolve(benchmark::State& state, const std::string& model, bool drift = false) {
  const Session s = MakeSession(model, static_cast<int>(state.range(0)), 1, drift);
  std::string error;
  for (auto _ : state) {
    Calibrator calibrator(s.options);
    for (const auto& r : s.records) calibrator.add_pose(r, &error);
    Estimate e = calibrator.solve();
    if (!e.ok) state.SkipWithError(e.error.c_str());
    benchmark::DoNotOptimize(e.theta.data());
  }
  state.SetComplexityN(state.range(0));
}

void BM_Accel13FullSolve(benchmark::State& state) { FullSolve(state, "accel13"); }
void BM_Mag13FullSolve(benchmark::State& state) { FullSolve(state, "mag13"); }
void BM_Mag22FullSolve(benchmark::State& state) { FullSolve(state, "mag22"); }
void BM_Accel13DriftFullSolve(benchmark::State& state) { FullSolve(state, "accel13", true); }

// The update after one more pose: a calibrator holding n poses and their estimate gets pose n+1
// and re-solves, warm-started.
void IncrementalAddPose(benchmark::State& state, bool drift, bool identify = false) {
  const int n = static_cast<int>(state.range(0));
  Session s = MakeSession("accel13", n + 1, 2, drift);
  s.options.identify_drift = identify;
  std::string error;
  for (auto _ : state) {
    state.PauseTiming();
    auto calibrator = std::make_unique<Calibrator>(s.options);
    for (int i = 0; i < n; ++i) calibrator->add_pose(s.records[i], &error);
    calibrator->solve();
    state.ResumeTiming();
    calibrator->add_pose(s.records[n], &error);
    Estimate e = calibrator->solve();
    benchmark::DoNotOptimize(e.theta.data());
    state.PauseTiming();
    calibrator.reset();
    state.ResumeTiming();
  }
}

void BM_Accel13IncrementalAddPose(benchmark::State& state) { IncrementalAddPose(state, false); }
void BM_Accel13DriftIncrementalAddPose(benchmark::State& state) { IncrementalAddPose(state, true); }
// The same with the drift's strength identified after the solve (the station's default).
void BM_Accel13IdentifyIncrementalAddPose(benchmark::State& state) {
  IncrementalAddPose(state, true, true);
}

// A full solve over these pose counts, in ms, with its complexity fitted.
void OverPoseCounts(benchmark::internal::Benchmark* b, std::initializer_list<int> counts) {
  for (int n : counts) b->Arg(n);
  b->Unit(benchmark::kMillisecond)->Complexity();
}

BENCHMARK(BM_Accel13FullSolve)->Apply([](benchmark::internal::Benchmark* b) {
  OverPoseCounts(b, {10, 26, 50, 100, 200, 500, 1000});
});
BENCHMARK(BM_Accel13IncrementalAddPose)->Arg(100)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Accel13DriftFullSolve)->Apply([](benchmark::internal::Benchmark* b) {
  OverPoseCounts(b, {26, 50, 100, 200});
});
BENCHMARK(BM_Accel13DriftIncrementalAddPose)->Arg(36)->Arg(100)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Accel13IdentifyIncrementalAddPose)->Arg(36)->Arg(100)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Mag13FullSolve)->Arg(50)->Arg(100)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Mag22FullSolve)->Apply([](benchmark::internal::Benchmark* b) {
  OverPoseCounts(b, {10, 50, 100, 200, 500, 1000});
});

}  // namespace
}  // namespace turncal

BENCHMARK_MAIN();
