// tests/bench/daemon_load_measure.h: `daemon_load measure`, step by step.
#include "daemon_load_measure.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <thread>
#include <utility>

namespace daemon_load {

std::optional<MeasureOptions> MeasureOptions::FromArgs(const Args& args) {
  MeasureOptions o;
  o.socket_path = args.Get("socket");
  o.seconds = args.Number("seconds", 60);
  o.n_clients = static_cast<int>(args.Number("clients", 4));
  o.n_devices = static_cast<int>(args.Number("devices", 8));
  o.rate_hz = args.Number("rate", 1000);
  o.interval_s = args.Number("interval", 10);
  o.warmup_timeout_s = args.Number("warmup-timeout", 180);
  o.settle_s = args.Number("settle", 2);
  o.daemon_pid = args.Get("daemon-pid");
  o.sim_pid = args.Get("sim-pid");
  o.json_out = args.Get("json-out");
  o.quiet_other = args.Number("quiet-other", 25);
  o.quiet_steal = args.Number("quiet-steal", 10);
  if (o.socket_path.empty() || !(o.seconds > 0) || o.n_clients < 0 || o.n_devices < 1) {
    std::fprintf(stderr, "daemon_load measure: --socket PATH and --seconds N > 0 are required\n");
    return std::nullopt;
  }
  return o;
}

LoadMeasurement::LoadMeasurement(MeasureOptions options)
    : o_(std::move(options)),
      ncpu_(static_cast<double>(std::thread::hardware_concurrency())),
      start_ns_(MonotonicNs()) {}

double LoadMeasurement::Elapsed() const {
  return static_cast<double>(MonotonicNs() - start_ns_) / 1e9;
}

// Subscribers (the socket may not be there yet).
bool LoadMeasurement::ConnectSubscribers() {
  for (int i = 0; i < o_.n_clients; ++i) {
    int fd = -1;
    while ((fd = Connect(o_.socket_path)) < 0 && Elapsed() < o_.warmup_timeout_s) {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    if (fd < 0) {
      std::fprintf(stderr, "daemon_load: nobody listens on %s\n", o_.socket_path.c_str());
      return false;
    }
    if (!SendAll(fd, "{\"cmd\":\"watch\",\"events\":false,\"corrected\":true}\n")) {
      std::fprintf(stderr, "daemon_load: cannot send the watch request\n");
      return false;
    }
    subs_.push_back(std::make_unique<Subscriber>(i, fd, &measuring_, &stop_));
    subs_.back()->Start();
  }
  return true;
}

void LoadMeasurement::StopAll() {
  stop_ = true;
  for (auto& s : subs_) s->Join();
}

// Warm-up without subscribers: every device streams.
bool LoadMeasurement::WaitForStreamingDevices() {
  while (true) {
    const json status = Request(o_.socket_path, "status", "STATUS");
    int streaming = 0;
    if (status.is_object()) {
      for (const auto& [name, d] : status["devices"].items()) {
        streaming +=
            d.value("state", "") == "streaming" && d["counters"].value("samples", 0ULL) > 0;
      }
    }
    if (streaming >= o_.n_devices) return true;
    if (Elapsed() > o_.warmup_timeout_s) {
      std::fprintf(stderr, "daemon_load: %d of %d devices streaming after %.0f s\n", streaming,
                   o_.n_devices, o_.warmup_timeout_s);
      return false;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
}

// Warm-up: every subscriber receives corrected samples of every device.
bool LoadMeasurement::WaitForSubscribers() {
  while (true) {
    bool ready = true;
    std::string missing;
    for (auto& s : subs_) {
      const auto c = s->counters();
      if (c.closed) {
        std::fprintf(stderr, "daemon_load: subscriber %d was closed by turncald during warm-up\n",
                     s->index());
        StopAll();
        return false;
      }
      if (static_cast<int>(c.devices.size()) < o_.n_devices) {
        ready = false;
        missing = std::to_string(c.devices.size()) + " of " + std::to_string(o_.n_devices);
      }
    }
    if (ready) return true;
    if (Elapsed() > o_.warmup_timeout_s) {
      std::fprintf(stderr,
                   "daemon_load: no corrected output from every device after %.0f s (%s devices "
                   "seen); status: %s\n",
                   o_.warmup_timeout_s, missing.c_str(),
                   Request(o_.socket_path, "status", "STATUS").dump().c_str());
      StopAll();
      return false;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
}

// The measurement: one row every interval until the window ends.
void LoadMeasurement::MeasureWindow() {
  status_before_ = Request(o_.socket_path, "status", "STATUS");
  first_ = Take(o_.daemon_pid, o_.sim_pid);
  measuring_ = true;
  previous_.resize(subs_.size());
  last_ = first_;
  if (first_.daemon.ok) {
    rss_t_.push_back(0);
    rss_mb_.push_back(first_.daemon.rss_mb);
  }
  std::printf("%7s %8s %7s %6s %6s %6s %6s %6s %6s %6s %8s %8s %8s %7s\n", "t_s", "daemon%",
              "rss_MB", "sim%", "subs%", "kwork%", "busy%", "other%", "steal%", "load1", "lines/s",
              "p99_ms", "p99.9_ms", "dropped");
  std::fflush(stdout);
  const std::int64_t end_ns = first_.t_ns + static_cast<std::int64_t>(o_.seconds * 1e9);
  std::uint64_t dropped_before = 0, lines_before = 0;
  for (std::int64_t next = first_.t_ns; next < end_ns;) {
    next = std::min(end_ns, next + static_cast<std::int64_t>(o_.interval_s * 1e9));
    while (MonotonicNs() < next) {
      std::this_thread::sleep_for(
          std::chrono::nanoseconds(std::min<std::int64_t>(next - MonotonicNs(), 100'000'000)));
    }
    const Snapshot now = Take(o_.daemon_pid, o_.sim_pid);
    const double wall = static_cast<double>(now.t_ns - last_.t_ns) / 1e9;
    const Row r = MeasureInterval(now, &dropped_before, &lines_before);
    rows_.push_back(r);
    if (now.daemon.ok) {
      rss_t_.push_back(r.t_s);
      rss_mb_.push_back(now.daemon.rss_mb);
    }
    PrintRow(r, wall);
    last_ = now;
  }
  measuring_ = false;
}

// The interval from last_ to `now`: the subscribers' latencies and counts since the last one,
// and the CPU of the daemon, the simulator, this tool, the kernel's workers and the rest.
Row LoadMeasurement::MeasureInterval(const Snapshot& now, std::uint64_t* dropped_before,
                                     std::uint64_t* lines_before) {
  const double wall = static_cast<double>(now.t_ns - last_.t_ns) / 1e9;
  Histogram interval;
  std::uint64_t dropped = 0, lines = 0;
  for (std::size_t i = 0; i < subs_.size(); ++i) {
    Histogram h = subs_[i]->Snapshot();
    interval.Merge(h.Minus(previous_[i]));
    previous_[i] = std::move(h);
    const auto c = subs_[i]->counters();
    dropped += c.dropped;
    lines += c.corrected;
  }
  Row r;
  r.t_s = static_cast<double>(now.t_ns - first_.t_ns) / 1e9;
  r.daemon_cpu = Percent(last_.daemon, now.daemon, wall);
  r.daemon_rss = now.daemon.ok ? now.daemon.rss_mb : -1;
  r.sim_cpu = Percent(last_.sim, now.sim, wall);
  r.self_cpu = Percent(last_.self, now.self, wall);
  const double total = now.system.total_s - last_.system.total_s;
  r.busy = total > 0 ? 100.0 * (now.system.busy_s - last_.system.busy_s) / total * ncpu_ : 0;
  r.load1 = now.system.load1;
  r.kworker = 100.0 * KworkerDelta(last_.system.kworker_s, now.system.kworker_s) / wall;
  kworker_total_s_ += r.kworker / 100.0 * wall;
  r.steal = total > 0 ? 100.0 * (now.system.steal_s - last_.system.steal_s) / total * ncpu_ : 0;
  r.other = r.busy - std::max(0.0, r.daemon_cpu) - std::max(0.0, r.sim_cpu) -
            std::max(0.0, r.self_cpu) - std::max(0.0, r.kworker);
  r.quiet = r.other < o_.quiet_other && r.steal < o_.quiet_steal;
  if (r.quiet) {
    quiet_.Merge(interval);
    ++quiet_intervals_;
    quiet_wall_ += wall;
    quiet_daemon_cpu_s_ += std::max(0.0, r.daemon_cpu) / 100.0 * wall;
  }
  r.lines = lines - *lines_before;
  r.p99_ms = interval.Quantile(0.99);
  r.p999_ms = interval.Quantile(0.999);
  r.dropped = dropped - *dropped_before;
  *dropped_before = dropped;
  *lines_before = lines;
  return r;
}

void LoadMeasurement::PrintRow(const Row& r, double wall) const {
  std::printf(
      "%7.1f %8.2f %7.1f %6.2f %6.2f %6.2f %6.1f %6.1f %6.1f %6.2f %8.0f %8.3f %8.3f %7llu%s\n",
      r.t_s, r.daemon_cpu, r.daemon_rss, r.sim_cpu, r.self_cpu, r.kworker, r.busy, r.other, r.steal,
      r.load1, static_cast<double>(r.lines) / wall, r.p99_ms, r.p999_ms,
      static_cast<unsigned long long>(r.dropped), r.quiet ? "" : "  (disturbed)");
  std::fflush(stdout);
}

// After the window: the subscribers' totals (then they stop), the CPU over the whole window, the
// worst interval, the devices' counters.
LoadMeasurement::Totals LoadMeasurement::Summarise() {
  const Snapshot& final_snapshot = last_;
  status_after_ = Request(o_.socket_path, "status", "STATUS");
  Totals t;
  for (auto& s : subs_) {
    const Histogram h = s->Snapshot();
    const auto c = s->counters();
    t.lost_subscriber = t.lost_subscriber || c.closed;
    t.all.Merge(h);
    t.corrected += c.corrected;
    t.dropped += c.dropped;
    t.clients.push_back({{"corrected", c.corrected},
                         {"p50_ms", h.Quantile(0.5)},
                         {"p99_ms", h.Quantile(0.99)},
                         {"p999_ms", h.Quantile(0.999)},
                         {"max_ms", h.max_ms()},
                         {"dropped", c.dropped},
                         {"dropped_notes", c.dropped_notes},
                         {"bytes", c.bytes},
                         {"errors", c.errors},
                         {"closed", c.closed}});
  }
  StopAll();

  t.wall = static_cast<double>(final_snapshot.t_ns - first_.t_ns) / 1e9;
  t.daemon_cpu = Percent(first_.daemon, final_snapshot.daemon, t.wall);
  t.sim_cpu = Percent(first_.sim, final_snapshot.sim, t.wall);
  t.self_cpu = Percent(first_.self, final_snapshot.self, t.wall);
  t.kworker_cpu = 100.0 * kworker_total_s_ / t.wall;
  const double total = final_snapshot.system.total_s - first_.system.total_s;
  t.busy =
      total > 0 ? 100.0 * (final_snapshot.system.busy_s - first_.system.busy_s) / total * ncpu_ : 0;
  t.steal = total > 0
                ? 100.0 * (final_snapshot.system.steal_s - first_.system.steal_s) / total * ncpu_
                : 0;
  for (const Row& r : rows_) {
    t.cpu_max = std::max(t.cpu_max, r.daemon_cpu);
    t.rss_max = std::max(t.rss_max, r.daemon_rss);
    t.busy_max = std::max(t.busy_max, r.busy);
    t.load_max = std::max(t.load_max, r.load1);
  }
  AddDeviceCounters(&t);
  t.expected = static_cast<double>(o_.n_devices) * o_.rate_hz * t.wall * o_.n_clients;
  t.rss_slope = Slope(rss_t_, rss_mb_) * 60.0;  // MB per minute
  t.p99 = t.all.Quantile(0.99);
  return t;
}

// Devices: samples decoded and lost during the window (the daemon's own counters).
void LoadMeasurement::AddDeviceCounters(Totals* t) const {
  const json before = DeviceCounters(status_before_), after = DeviceCounters(status_after_);
  for (const auto& item : after.items()) {
    const std::string& name = item.key();
    const json& a = item.value();
    const json b = before.value(name, json::object());
    const auto delta = [&](const char* key) { return a.value(key, 0ULL) - b.value(key, 0ULL); };
    t->devices[name] = {{"samples", delta("samples")},
                        {"lost_samples", delta("lost_samples")},
                        {"bad_checksums", delta("bad_checksums")},
                        {"skipped_bytes", delta("skipped_bytes")},
                        {"state", a.value("state", "")}};
    t->samples_per_s += static_cast<double>(delta("samples")) / t->wall;
    t->lost += delta("lost_samples");
    t->bad += delta("bad_checksums");
  }
}

namespace {

// One row per interval, as in the table printed during the window.
json IntervalsJson(const std::vector<Row>& rows) {
  json a = json::array();
  for (const Row& r : rows) {
    a.push_back({{"t_s", r.t_s},
                 {"daemon_cpu_pct", r.daemon_cpu},
                 {"rss_mb", r.daemon_rss},
                 {"sim_cpu_pct", r.sim_cpu},
                 {"busy_pct", r.busy},
                 {"kworker_pct", r.kworker},
                 {"other_pct", r.other},
                 {"steal_pct", r.steal},
                 {"undisturbed", r.quiet},
                 {"load1", r.load1},
                 {"lines", r.lines},
                 {"p99_ms", r.p99_ms},
                 {"p999_ms", r.p999_ms},
                 {"dropped", r.dropped}});
  }
  return a;
}

}  // namespace

// The LOAD_RESULT line (and --json-out).
json LoadMeasurement::Result(const Totals& t) const {
  return {
      {"class", "LOAD_RESULT"},
      {"seconds", t.wall},
      {"devices", o_.n_devices},
      {"rate_hz", o_.rate_hz},
      {"clients", o_.n_clients},
      {"daemon_cpu_pct", t.daemon_cpu},
      {"daemon_cpu_pct_max_interval", t.cpu_max},
      {"sim_cpu_pct", t.sim_cpu},
      {"subscribers_cpu_pct", t.self_cpu},
      {"kworker_cpu_pct", t.kworker_cpu},
      {"machine_busy_pct_of_one_core", t.busy},
      {"machine_busy_pct_max_interval", t.busy_max},
      {"steal_pct_of_one_core", t.steal},
      {"load1_max", t.load_max},
      {"latency_ms",
       {{"count", t.all.count()},
        {"mean", t.all.mean_ms()},
        {"p50", t.all.Quantile(0.5)},
        {"p90", t.all.Quantile(0.9)},
        {"p99", t.p99},
        {"p999", t.all.Quantile(0.999)},
        {"max", t.all.max_ms()},
        {"above_2ms_fraction", t.all.FractionAbove(2.0)},
        {"negative", t.all.negative()}}},
      {"undisturbed",
       {{"other_below_pct", o_.quiet_other},
        {"steal_below_pct", o_.quiet_steal},
        {"intervals", quiet_intervals_},
        {"of", rows_.size()},
        {"daemon_cpu_pct", quiet_wall_ > 0 ? 100.0 * quiet_daemon_cpu_s_ / quiet_wall_ : -1.0},
        {"latency_ms",
         {{"count", quiet_.count()},
          {"p50", quiet_.Quantile(0.5)},
          {"p90", quiet_.Quantile(0.9)},
          {"p99", quiet_.Quantile(0.99)},
          {"p999", quiet_.Quantile(0.999)},
          {"above_2ms_fraction", quiet_.FractionAbove(2.0)}}}}},
      {"corrected_lines", t.corrected},
      {"corrected_lines_expected", t.expected},
      {"dropped", t.dropped},
      {"daemon_samples_per_s", t.samples_per_s},
      {"lost_samples", t.lost},
      {"bad_checksums", t.bad},
      {"rss_mb",
       {{"start", rss_mb_.empty() ? -1 : rss_mb_.front()},
        {"max", t.rss_max},
        {"end", rss_mb_.empty() ? -1 : rss_mb_.back()},
        {"hwm", last_.daemon.hwm_mb},
        {"slope_mb_per_min", t.rss_slope}}},
      // The daemon's own timing: the loop's longest turn with a captured pose (loop_ms) and the
      // solve worker's longest pose update (solve_ms), when it reports them.
      {"loop_ms", status_after_.is_object() ? status_after_.value("loop_ms", json()) : json()},
      {"solve_ms", status_after_.is_object() ? status_after_.value("solve_ms", json()) : json()},
      {"per_client", t.clients},
      {"per_device", t.devices},
      {"intervals", IntervalsJson(rows_)}};
}

// The summary with the targets (docs/PERFORMANCE.md), met or missed.
void LoadMeasurement::PrintSummary(const Totals& t) const {
  auto verdict = [](bool ok) { return ok ? "meets" : "MISSES"; };
  std::printf(
      "\nturncald under load: %d devices x %.0f Hz, %d subscribers to corrected output, "
      "%.1f s\n",
      o_.n_devices, o_.rate_hz, o_.n_clients, t.wall);
  std::printf(
      "  daemon CPU        %6.2f %% of one core (max interval %.2f %%)   target <= 10 %%: %s\n",
      t.daemon_cpu, t.cpu_max, verdict(t.daemon_cpu >= 0 && t.daemon_cpu <= 10.0));
  std::printf(
      "  latency           p50 %.3f  p90 %.3f  p99 %.3f  p99.9 %.3f  max %.3f ms "
      "(%llu lines, %.4f %% > 2 ms)   target p99 <= 2 ms: %s\n",
      t.all.Quantile(0.5), t.all.Quantile(0.9), t.p99, t.all.Quantile(0.999), t.all.max_ms(),
      static_cast<unsigned long long>(t.all.count()), 100.0 * t.all.FractionAbove(2.0),
      verdict(t.all.count() > 0 && t.p99 <= 2.0));
  std::printf(
      "  daemon RSS        start %.1f  max %.1f  end %.1f MB, slope %+.3f MB/min, "
      "VmHWM %.1f MB   target <= 50 MB, flat: %s\n",
      rss_mb_.empty() ? -1.0 : rss_mb_.front(), t.rss_max, rss_mb_.empty() ? -1.0 : rss_mb_.back(),
      t.rss_slope, last_.daemon.hwm_mb, verdict(t.rss_max > 0 && t.rss_max <= 50.0));
  std::printf(
      "  delivered         %llu corrected lines of %.0f expected (%.2f %%), %llu dropped; "
      "daemon decoded %.0f samples/s, %llu lost, %llu bad checksums\n",
      static_cast<unsigned long long>(t.corrected), t.expected,
      t.expected > 0 ? 100.0 * static_cast<double>(t.corrected) / t.expected : 0.0,
      static_cast<unsigned long long>(t.dropped), t.samples_per_s,
      static_cast<unsigned long long>(t.lost), static_cast<unsigned long long>(t.bad));
  std::printf(
      "  other processes   simulator %.2f %%, subscribers (this tool) %.2f %%, kernel "
      "workers %.2f %%; machine busy %.1f %% of one core (of %u), hypervisor steal %.1f %%, load1 "
      "max %.2f\n",
      t.sim_cpu, t.self_cpu, t.kworker_cpu, t.busy, std::thread::hardware_concurrency(), t.steal,
      t.load_max);
  std::printf(
      "  undisturbed       %d of %zu intervals with the rest of the machine below %.0f %% "
      "of a core and steal below %.0f %%: daemon CPU %.2f %%, latency p50 %.3f  p90 %.3f  p99 %.3f "
      " p99.9 %.3f ms "
      "(%llu lines)\n",
      quiet_intervals_, rows_.size(), o_.quiet_other, o_.quiet_steal,
      quiet_wall_ > 0 ? 100.0 * quiet_daemon_cpu_s_ / quiet_wall_ : -1.0, quiet_.Quantile(0.5),
      quiet_.Quantile(0.9), quiet_.Quantile(0.99), quiet_.Quantile(0.999),
      static_cast<unsigned long long>(quiet_.count()));
  if (status_after_.is_object()) {
    std::printf("  daemon status     loop_ms %s, solve_ms %s\n",
                status_after_.value("loop_ms", json()).dump().c_str(),
                status_after_.value("solve_ms", json()).dump().c_str());
  }
}

int LoadMeasurement::Run() {
  if (!ConnectSubscribers()) return 1;
  if (o_.n_clients == 0 && !WaitForStreamingDevices()) return 1;
  if (o_.n_clients > 0 && !WaitForSubscribers()) return 1;
  std::printf("daemon_load: corrected output from %d devices on %d subscribers after %.1f s\n",
              o_.n_devices, o_.n_clients, Elapsed());  // (the script waits for this line)
  std::this_thread::sleep_for(std::chrono::duration<double>(o_.settle_s));

  MeasureWindow();
  const Totals t = Summarise();
  const json result = Result(t);
  PrintSummary(t);
  std::printf("%s\n", result.dump().c_str());
  if (!o_.json_out.empty()) std::ofstream(o_.json_out) << result.dump(2) << "\n";
  if (t.lost_subscriber || (o_.n_clients > 0 && t.all.count() == 0)) {
    std::fprintf(stderr, "daemon_load: %s\n",
                 t.lost_subscriber ? "a subscriber was closed during the measurement"
                                   : "no corrected line was measured");
    return 1;
  }
  return 0;
}

int Measure(const Args& args) {
  const std::optional<MeasureOptions> options = MeasureOptions::FromArgs(args);
  if (!options) return 2;
  return LoadMeasurement(*options).Run();
}

}  // namespace daemon_load
