// `daemon_load measure` (tests/bench/daemon_load.cc): subscribers connected, a warm-up until
// corrected output flows from every device, the window measured interval by interval, and the
// summary and LOAD_RESULT line.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "daemon_load_probes.h"
#include "daemon_load_subscriber.h"

namespace daemon_load {

struct MeasureOptions {
  std::string socket_path;
  double seconds = 60;
  int n_clients = 4;
  int n_devices = 8;
  double rate_hz = 1000;
  double interval_s = 10;
  double warmup_timeout_s = 180;
  double settle_s = 2;
  std::string daemon_pid, sim_pid;
  std::string json_out;
  // An interval is undisturbed when the rest of the machine (other builds, tests) used less than
  // quiet_other (% of one core) and the hypervisor took less than quiet_steal: its latencies also
  // go into a separate histogram.
  double quiet_other = 25;
  double quiet_steal = 10;

  // The options of `daemon_load measure`; nullopt (said on stderr) when they are incomplete.
  static std::optional<MeasureOptions> FromArgs(const Args& args);
};

// One interval of the window.
struct Row {
  double t_s = 0;
  double daemon_cpu = -1, daemon_rss = -1, sim_cpu = -1, self_cpu = -1, busy = 0, load1 = 0;
  double kworker = 0, steal = 0;
  double other = 0;  // machine busy time that is none of daemon, simulator, subscribers, kworkers
  bool quiet = false;
  std::uint64_t lines = 0;
  double p99_ms = 0, p999_ms = 0;
  std::uint64_t dropped = 0;
};

class LoadMeasurement {
 public:
  explicit LoadMeasurement(MeasureOptions options);
  // The exit code: 0 when the run completed, 1 when it could not measure.
  int Run();

 private:
  // What the window adds up to.
  struct Totals {
    bool lost_subscriber = false;
    Histogram all;
    json clients = json::array();
    std::uint64_t corrected = 0, dropped = 0;
    double wall = 0, daemon_cpu = 0, sim_cpu = 0, self_cpu = 0, kworker_cpu = 0, busy = 0,
           steal = 0;
    double cpu_max = 0, rss_max = 0, busy_max = 0, load_max = 0;
    json devices = json::object();
    double samples_per_s = 0;
    std::uint64_t lost = 0, bad = 0;
    double expected = 0, rss_slope = 0, p99 = 0;
  };

  double Elapsed() const;
  bool ConnectSubscribers();
  void StopAll();
  bool WaitForStreamingDevices();
  bool WaitForSubscribers();
  void MeasureWindow();
  Row MeasureInterval(const Snapshot& now, std::uint64_t* dropped_before,
                      std::uint64_t* lines_before);
  void PrintRow(const Row& r, double wall) const;
  Totals Summarise();
  void AddDeviceCounters(Totals* t) const;
  json Result(const Totals& t) const;
  void PrintSummary(const Totals& t) const;

  MeasureOptions o_;
  double ncpu_;
  std::int64_t start_ns_;
  std::atomic<bool> measuring_{false}, stop_{false};
  std::vector<std::unique_ptr<Subscriber>> subs_;
  json status_before_, status_after_;
  Snapshot first_, last_;
  std::vector<Row> rows_;
  std::vector<Histogram> previous_;  // each subscriber's histogram at the last interval
  std::vector<double> rss_t_, rss_mb_;
  Histogram quiet_;
  double kworker_total_s_ = 0;
  int quiet_intervals_ = 0;
  double quiet_wall_ = 0, quiet_daemon_cpu_s_ = 0;
};

// `daemon_load measure ARGS`.
int Measure(const Args& args);

}  // namespace daemon_load
