#pragma once
// The Monte Carlo engines' runs, `jobs` threads at a time, each run filling its own slot: the
// results come out in run order whatever the threads' timing, so a seed gives the same output
// with any --jobs.

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

namespace turncal::montecarlo {

// run(i, &out[i]) for every i in [0, count), on max(1, jobs) threads.
template <typename Run, typename OneRun>
std::vector<Run> RunInParallel(int count, int jobs, OneRun run) {
  std::vector<Run> out(static_cast<std::size_t>(std::max(count, 0)));
  std::atomic<int> next{0};
  auto worker = [&] {
    for (int i = next++; i < count; i = next++) run(i, &out[static_cast<std::size_t>(i)]);
  };
  std::vector<std::thread> threads;
  for (int j = 0; j < std::max(1, jobs); ++j) threads.emplace_back(worker);
  for (auto& t : threads) t.join();
  return out;
}

// A scratch folder for one engine's runs: DIR/NAME-PID under the system's temporary directory.
inline std::filesystem::path ScratchDir(const std::string& name) {
  return std::filesystem::temp_directory_path() /
         (name + "-" + std::to_string(static_cast<long>(::getpid())));
}

// RunInParallel's runs with a scratch folder (ScratchDir(name), `*dir`) made before them and
// removed with what they left in it after them.
template <typename Run, typename OneRun>
std::vector<Run> RunInScratchDir(const std::string& name, int count, int jobs,
                                 std::filesystem::path* dir, OneRun run) {
  *dir = ScratchDir(name);
  std::filesystem::create_directories(*dir);
  std::vector<Run> runs = RunInParallel<Run>(count, jobs, run);
  std::filesystem::remove_all(*dir);
  return runs;
}

}  // namespace turncal::montecarlo
