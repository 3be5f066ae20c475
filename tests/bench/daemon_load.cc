// turncald under load: subscribers to corrected output, latency from byte arrival to a
// subscriber, and the daemon's CPU and memory (docs/PERFORMANCE.md, "Daemon under load").
// tests/bench/daemon_load.sh runs the whole set-up (simulator on ptys, turncald, this tool).
//
//   daemon_load seed --truth TRUTH.json --state-dir DIR [--prefix imu]
//       Writes DIR/calibrations/<prefix><i>.<model>.json (schema 1, version 1) for every device
//       of a `turncal sim --truth-out` file, with the true parameters, so that turncald corrects
//       from its first sample (Station::LoadApplied) instead of after ~13 poses.
//
//   daemon_load measure --socket PATH --seconds N [--clients 4] [--devices 8] [--rate 1000]
//                       [--interval 10] [--daemon-pid P] [--sim-pid P] [--warmup-timeout 180]
//                       [--settle 2] [--quiet-other 25] [--quiet-steal 10] [--json-out FILE]
//       Connects --clients subscribers, each sending {"cmd":"watch","events":false,
//       "corrected":true}, one thread each (blocking reads; a thread costs far less than the
//       daemon's side of the stream). Waits until every subscriber has CORRECTED lines from
//       --devices devices (--clients 0: until every device streams, for the daemon's cost without
//       subscribers), then measures for N seconds: for every CORRECTED line the latency
//       CLOCK_MONOTONIC at receipt (the read() that returned it) minus its t_host_ns (the time
//       turncald read the bytes from the pty), DROPPED notes, and every --interval seconds the
//       CPU (utime+stime) and VmRSS of the daemon, of the simulator and of this process, the
//       machine's busy time (/proc/stat) and load average. This machine is shared: an interval in
//       which the rest of the machine (busy time minus daemon, simulator and subscribers) used
//       --quiet-other % of a core or more, or the hypervisor took --quiet-steal % of a core (steal
//       time: the host ran somebody else on our virtual CPUs), is marked "disturbed"; the summary
//       gives the latency of the undisturbed intervals separately. Device counters come from the
//       daemon's status before and after. Prints one row per interval, a summary, and a final
//       line {"class":"LOAD_RESULT",...}; exit 0 when the run completed (targets are reported,
//       not enforced), 1 when it could not measure (no corrected output, a subscriber lost).
#include <fcntl.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace {

using nlohmann::json;

std::int64_t MonotonicNs() {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// ---------------------------------------------------------------------------------------------
// Command line: --key value pairs.

struct Args {
  std::map<std::string, std::string> values;
  std::string Get(const std::string& key, const std::string& fallback = "") const {
    auto it = values.find(key);
    return it == values.end() ? fallback : it->second;
  }
  double Number(const std::string& key, double fallback) const {
    auto it = values.find(key);
    return it == values.end() ? fallback : std::strtod(it->second.c_str(), nullptr);
  }
};

bool ParseArgs(int argc, char** argv, int first, Args* args) {
  for (int i = first; i < argc; ++i) {
    const std::string a = argv[i];
    if (a.rfind("--", 0) != 0 || i + 1 >= argc) {
      std::fprintf(stderr, "daemon_load: expected --key value, got '%s'\n", a.c_str());
      return false;
    }
    args->values[a.substr(2)] = argv[++i];
  }
  return true;
}

// ---------------------------------------------------------------------------------------------
// seed

int Seed(const Args& args) {
  namespace fs = std::filesystem;
  const std::string truth_path = args.Get("truth"), state_dir = args.Get("state-dir");
  const std::string prefix = args.Get("prefix", "imu");
  if (truth_path.empty() || state_dir.empty()) {
    std::fprintf(stderr, "daemon_load seed: --truth FILE and --state-dir DIR are required\n");
    return 2;
  }
  std::ifstream in(truth_path);
  const json truth = json::parse(in, nullptr, false);
  if (truth.is_discarded() || !truth.contains("devices") || !truth["devices"].is_array()) {
    std::fprintf(stderr, "daemon_load seed: %s: not a `turncal sim --controller` truth file\n",
                 truth_path.c_str());
    return 1;
  }
  const fs::path dir = fs::path(state_dir) / "calibrations";
  fs::create_directories(dir);
  int written = 0;
  for (std::size_t i = 0; i < truth["devices"].size(); ++i) {
    const std::string device = prefix + std::to_string(i + 1);
    for (const auto& [model, params] : truth["devices"][i]["models"].items()) {
      json p = json::object();
      for (const auto& [name, value] : params.items()) {
        p[name] = {{"value", value}, {"sigma", nullptr}};
      }
      const json calibration = {
          {"schema", 1},
          {"class", "CALIBRATION"},
          {"device", device},
          {"model", model},
          {"version", 1},
          {"software", "tests/bench/daemon_load seed"},
          {"params", p},
          {"note", "the simulator's true parameters, seeded for a load measurement"}};
      std::ofstream out(dir / (device + "." + model + ".json"));
      out << calibration.dump(2) << "\n";
      if (!out) {
        std::fprintf(stderr, "daemon_load seed: cannot write in %s\n", dir.c_str());
        return 1;
      }
      ++written;
    }
  }
  std::printf("daemon_load seed: %d calibrations in %s\n", written, dir.c_str());
  return 0;
}

// ---------------------------------------------------------------------------------------------
// /proc

long ClockTicks() {
  static const long ticks = ::sysconf(_SC_CLK_TCK);
  return ticks;
}

struct ProcSample {
  bool ok = false;
  double cpu_s = 0;  // utime + stime
  double rss_mb = 0;
  double hwm_mb = 0;
};

ProcSample ReadProc(const std::string& pid) {
  ProcSample p;
  std::ifstream stat("/proc/" + pid + "/stat");
  std::string text;
  if (!std::getline(stat, text)) return p;
  const auto close = text.rfind(')');
  if (close == std::string::npos) return p;
  std::istringstream fields(text.substr(close + 2));
  std::vector<std::string> f;
  for (std::string s; fields >> s;) f.push_back(s);
  // After "pid (comm) ": state is field 3, utime 14 and stime 15 (1-based) -> f[11], f[12].
  if (f.size() < 13) return p;
  p.cpu_s = (std::strtod(f[11].c_str(), nullptr) + std::strtod(f[12].c_str(), nullptr)) /
            static_cast<double>(ClockTicks());
  std::ifstream status("/proc/" + pid + "/status");
  for (std::string line; std::getline(status, line);) {
    if (line.rfind("VmRSS:", 0) == 0) p.rss_mb = std::strtod(line.c_str() + 6, nullptr) / 1024.0;
    if (line.rfind("VmHWM:", 0) == 0) p.hwm_mb = std::strtod(line.c_str() + 6, nullptr) / 1024.0;
  }
  p.ok = true;
  return p;
}

struct SystemSample {
  double busy_s = 0, total_s = 0, steal_s = 0;  // busy: user, nice, system, irq, softirq
  double load1 = 0;
  std::map<std::string, double> kworker_s;  // kernel workers (the tty layer moves pty bytes)
};

// CPU time of every kworker thread so far, by pid (threads that end between two samples lose
// their last part: an estimate).
std::map<std::string, double> KworkerSeconds() {
  namespace fs = std::filesystem;
  std::map<std::string, double> out;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator("/proc", ec)) {
    const std::string name = entry.path().filename().string();
    if (name.empty() || name.find_first_not_of("0123456789") != std::string::npos) continue;
    std::ifstream comm(entry.path() / "comm");
    std::string c;
    if (!std::getline(comm, c) || c.rfind("kworker", 0) != 0) continue;
    const ProcSample p = ReadProc(name);
    if (p.ok) out[name] = p.cpu_s;
  }
  return out;
}

// Seconds the kworkers of `now` ran since `before` (new ones: all of their time).
double KworkerDelta(const std::map<std::string, double>& before,
                    const std::map<std::string, double>& now) {
  double sum = 0;
  for (const auto& [pid, t] : now) {
    const auto it = before.find(pid);
    sum += std::max(0.0, t - (it == before.end() ? 0.0 : it->second));
  }
  return sum;
}

SystemSample ReadSystem() {
  SystemSample s;
  std::ifstream stat("/proc/stat");
  std::string cpu;
  stat >> cpu;
  std::vector<double> v;
  for (int i = 0; i < 8; ++i) {
    double x = 0;
    stat >> x;
    v.push_back(x);
  }
  // user nice system idle iowait irq softirq steal; steal is time the hypervisor gave our
  // virtual CPUs to somebody else.
  double total = 0;
  for (double x : v) total += x;
  s.total_s = total / static_cast<double>(ClockTicks());
  s.busy_s = (total - v[3] - v[4] - v[7]) / static_cast<double>(ClockTicks());
  s.steal_s = v[7] / static_cast<double>(ClockTicks());
  std::ifstream load("/proc/loadavg");
  load >> s.load1;
  s.kworker_s = KworkerSeconds();
  return s;
}

// ---------------------------------------------------------------------------------------------
// Sockets

int Connect(const std::string& path) {
  sockaddr_un address{};
  address.sun_family = AF_UNIX;
  if (path.size() >= sizeof(address.sun_path)) return -1;
  std::memcpy(address.sun_path, path.data(), path.size());
  const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return -1;
  if (::connect(fd, reinterpret_cast<const sockaddr*>(&address), sizeof(address)) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}

bool SendAll(int fd, const std::string& text) {
  std::size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::send(fd, text.data() + done, text.size() - done, MSG_NOSIGNAL);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    done += static_cast<std::size_t>(n);
  }
  return true;
}

// One request on its own connection: the reply of the given class (or null).
json Request(const std::string& path, const std::string& cmd, const std::string& reply_class) {
  const int fd = Connect(path);
  if (fd < 0) return nullptr;
  json reply;
  if (SendAll(fd, json{{"cmd", cmd}}.dump() + "\n")) {
    std::string buffer;
    char chunk[65536];
    const std::int64_t deadline = MonotonicNs() + 5'000'000'000;
    while (reply.is_null() && MonotonicNs() < deadline) {
      pollfd p{fd, POLLIN, 0};
      if (::poll(&p, 1, 200) <= 0) continue;
      const ssize_t n = ::recv(fd, chunk, sizeof(chunk), 0);
      if (n <= 0) break;
      buffer.append(chunk, static_cast<std::size_t>(n));
      for (auto nl = buffer.find('\n'); nl != std::string::npos; nl = buffer.find('\n')) {
        json j = json::parse(buffer.substr(0, nl), nullptr, false);
        buffer.erase(0, nl + 1);
        if (!j.is_discarded() && j.value("class", "") == reply_class) {
          reply = std::move(j);
          break;
        }
      }
    }
  }
  ::close(fd);
  return reply;
}

// ---------------------------------------------------------------------------------------------
// Latency histogram: 1 us buckets up to 100 ms, 100 us buckets up to 10 s, the rest counted
// with the maximum.

class Histogram {
 public:
  static constexpr std::size_t kFine = 100'000;            // 1 us each
  static constexpr std::size_t kBuckets = kFine + 99'000;  // then 100 us each
  static std::size_t Bucket(std::int64_t us) {
    const auto u = static_cast<std::size_t>(us);
    return u < kFine ? u : kFine + (u - kFine) / 100;
  }
  // The upper edge of a bucket, in ms.
  static double UpperMs(std::size_t i) {
    return i < kFine ? static_cast<double>(i + 1) / 1000.0
                     : static_cast<double>(kFine + (i - kFine + 1) * 100) / 1000.0;
  }
  Histogram() : counts_(kBuckets, 0) {}
  void Add(std::int64_t ns) {
    ++count_;
    max_ns_ = std::max(max_ns_, ns);
    if (ns < 0) {
      ++negative_;
      ns = 0;
    }
    const std::size_t b = Bucket(ns / 1000);
    if (b < kBuckets) {
      ++counts_[b];
    } else {
      ++over_;
    }
    sum_ns_ += static_cast<double>(ns);
  }
  void Merge(const Histogram& o) {
    for (std::size_t i = 0; i < kBuckets; ++i) counts_[i] += o.counts_[i];
    count_ += o.count_;
    over_ += o.over_;
    negative_ += o.negative_;
    max_ns_ = std::max(max_ns_, o.max_ns_);
    sum_ns_ += o.sum_ns_;
  }
  // this - earlier (an interval of a cumulative histogram); the maximum is not kept.
  Histogram Minus(const Histogram& earlier) const {
    Histogram h;
    for (std::size_t i = 0; i < kBuckets; ++i) h.counts_[i] = counts_[i] - earlier.counts_[i];
    h.count_ = count_ - earlier.count_;
    h.over_ = over_ - earlier.over_;
    h.negative_ = negative_ - earlier.negative_;
    h.sum_ns_ = sum_ns_ - earlier.sum_ns_;
    h.max_ns_ = -1;
    return h;
  }
  std::uint64_t count() const { return count_; }
  std::uint64_t negative() const { return negative_; }
  double max_ms() const { return static_cast<double>(max_ns_) / 1e6; }
  double mean_ms() const { return count_ ? sum_ns_ / static_cast<double>(count_) / 1e6 : 0; }
  // The q-quantile in ms (upper edge of its bucket); above 10 s: the maximum.
  double Quantile(double q) const {
    if (count_ == 0) return 0;
    const auto rank = static_cast<std::uint64_t>(std::ceil(q * static_cast<double>(count_)));
    std::uint64_t seen = 0;
    for (std::size_t i = 0; i < kBuckets; ++i) {
      seen += counts_[i];
      if (seen >= rank && seen > 0) return UpperMs(i);
    }
    return max_ms();
  }
  // Fraction of samples above `ms`.
  double FractionAbove(double ms) const {
    if (count_ == 0) return 0;
    const std::size_t limit = Bucket(static_cast<std::int64_t>(ms * 1000.0));
    std::uint64_t above = over_;
    for (std::size_t i = limit; i < kBuckets; ++i) above += counts_[i];
    return static_cast<double>(above) / static_cast<double>(count_);
  }

 private:
  std::vector<std::uint32_t> counts_;
  std::uint64_t count_ = 0, over_ = 0, negative_ = 0;
  std::int64_t max_ns_ = 0;
  double sum_ns_ = 0;
};

// ---------------------------------------------------------------------------------------------
// A subscriber

class Subscriber {
 public:
  Subscriber(int index, int fd, std::atomic<bool>* measuring, std::atomic<bool>* stop)
      : index_(index), fd_(fd), measuring_(measuring), stop_(stop) {}
  ~Subscriber() {
    if (thread_.joinable()) thread_.join();
    if (fd_ >= 0) ::close(fd_);
  }
  void Start() {
    thread_ = std::thread([this] { Run(); });
  }
  void Join() {
    if (thread_.joinable()) thread_.join();
  }

  // Copies under the lock.
  Histogram Snapshot() {
    std::lock_guard lock(mutex_);
    return hist_;
  }
  struct Counters {
    std::uint64_t lines = 0, corrected = 0, dropped_notes = 0, dropped = 0, bytes = 0, errors = 0,
                  unparsed = 0;
    std::set<std::string> devices;  // seen before the measurement (warm-up)
    bool closed = false;
    std::string last_error;
  };
  Counters counters() {
    std::lock_guard lock(mutex_);
    return counters_;
  }
  int index() const { return index_; }

 private:
  void Run() {
    std::string buffer;
    std::vector<char> chunk(1 << 16);
    while (!stop_->load()) {
      pollfd p{fd_, POLLIN, 0};
      const int r = ::poll(&p, 1, 200);
      if (r <= 0) continue;
      const ssize_t n = ::recv(fd_, chunk.data(), chunk.size(), 0);
      const std::int64_t now = MonotonicNs();
      if (n <= 0) {
        if (n < 0 && errno == EINTR) continue;
        std::lock_guard lock(mutex_);
        counters_.closed = true;
        return;
      }
      buffer.append(chunk.data(), static_cast<std::size_t>(n));
      const bool measuring = measuring_->load();
      std::lock_guard lock(mutex_);
      if (measuring) counters_.bytes += static_cast<std::size_t>(n);
      std::size_t start = 0;
      for (auto nl = buffer.find('\n'); nl != std::string::npos; nl = buffer.find('\n', start)) {
        OnLine(std::string_view(buffer).substr(start, nl - start), now, measuring);
        start = nl + 1;
      }
      buffer.erase(0, start);
    }
  }

  void OnLine(std::string_view line, std::int64_t now, bool measuring) {
    static constexpr std::string_view kCorrected = "{\"class\":\"CORRECTED\"";
    static constexpr std::string_view kTime = "\"t_host_ns\":";
    static constexpr std::string_view kDevice = "\"device\":\"";
    static constexpr std::string_view kDropped = "{\"class\":\"DROPPED\"";
    if (measuring) ++counters_.lines;
    if (line.substr(0, kCorrected.size()) == kCorrected) {
      const auto t = line.find(kTime);
      if (t == std::string_view::npos) {
        ++counters_.unparsed;
        return;
      }
      const std::int64_t t_host = std::strtoll(line.data() + t + kTime.size(), nullptr, 10);
      if (measuring) {
        ++counters_.corrected;
        hist_.Add(now - t_host);
      } else {
        const auto d = line.find(kDevice);
        if (d != std::string_view::npos) {
          const auto begin = d + kDevice.size();
          const auto end = line.find('"', begin);
          if (end != std::string_view::npos) {
            counters_.devices.emplace(line.substr(begin, end - begin));
          }
        }
      }
      return;
    }
    if (line.substr(0, kDropped.size()) == kDropped) {
      const json j = json::parse(line, nullptr, false);
      if (measuring && !j.is_discarded()) {
        ++counters_.dropped_notes;
        counters_.dropped += j.value("count", 0ULL);
      }
      return;
    }
    if (line.find("\"class\":\"ERROR\"") != std::string_view::npos) {
      ++counters_.errors;
      counters_.last_error = std::string(line);
    }
  }

  int index_;
  int fd_;
  std::atomic<bool>* measuring_;
  std::atomic<bool>* stop_;
  std::thread thread_;
  std::mutex mutex_;
  Histogram hist_;
  Counters counters_;
};

// ---------------------------------------------------------------------------------------------
// measure

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

struct Snapshot {
  std::int64_t t_ns = 0;
  ProcSample daemon, sim, self;
  SystemSample system;
};

Snapshot Take(const std::string& daemon_pid, const std::string& sim_pid) {
  Snapshot s;
  s.t_ns = MonotonicNs();
  if (!daemon_pid.empty()) s.daemon = ReadProc(daemon_pid);
  if (!sim_pid.empty()) s.sim = ReadProc(sim_pid);
  s.self = ReadProc("self");
  s.system = ReadSystem();
  return s;
}

double Percent(const ProcSample& a, const ProcSample& b, double wall_s) {
  if (!a.ok || !b.ok || wall_s <= 0) return -1;
  return 100.0 * (b.cpu_s - a.cpu_s) / wall_s;
}

// Least-squares slope of y over x.
double Slope(const std::vector<double>& x, const std::vector<double>& y) {
  const std::size_t n = x.size();
  if (n < 2) return 0;
  double mx = 0, my = 0;
  for (std::size_t i = 0; i < n; ++i) {
    mx += x[i];
    my += y[i];
  }
  mx /= static_cast<double>(n);
  my /= static_cast<double>(n);
  double sxy = 0, sxx = 0;
  for (std::size_t i = 0; i < n; ++i) {
    sxy += (x[i] - mx) * (y[i] - my);
    sxx += (x[i] - mx) * (x[i] - mx);
  }
  return sxx > 0 ? sxy / sxx : 0;
}

json DeviceCounters(const json& status) {
  json out = json::object();
  if (!status.is_object() || !status.contains("devices")) return out;
  for (const auto& [name, d] : status["devices"].items()) {
    out[name] = d.value("counters", json::object());
    out[name]["state"] = d.value("state", "");
    out[name]["rate_hz"] = d.value("rate_hz", 0.0);
  }
  return out;
}

int Measure(const Args& args) {
  const std::string socket_path = args.Get("socket");
  const double seconds = args.Number("seconds", 60);
  const int n_clients = static_cast<int>(args.Number("clients", 4));
  const int n_devices = static_cast<int>(args.Number("devices", 8));
  const double rate_hz = args.Number("rate", 1000);
  const double interval_s = args.Number("interval", 10);
  const double warmup_timeout_s = args.Number("warmup-timeout", 180);
  const double settle_s = args.Number("settle", 2);
  const std::string daemon_pid = args.Get("daemon-pid"), sim_pid = args.Get("sim-pid");
  const std::string json_out = args.Get("json-out");
  // An interval is undisturbed when the rest of the machine (other builds, tests) used less than
  // this (% of one core): its latencies also go into a separate histogram.
  const double quiet_other = args.Number("quiet-other", 25);
  const double quiet_steal = args.Number("quiet-steal", 10);  // and the hypervisor took less
  if (socket_path.empty() || !(seconds > 0) || n_clients < 0 || n_devices < 1) {
    std::fprintf(stderr, "daemon_load measure: --socket PATH and --seconds N > 0 are required\n");
    return 2;
  }
  const double ncpu = static_cast<double>(std::thread::hardware_concurrency());
  auto elapsed_s = [start = MonotonicNs()] {
    return static_cast<double>(MonotonicNs() - start) / 1e9;
  };

  // Subscribers (the socket may not be there yet).
  std::atomic<bool> measuring{false}, stop{false};
  std::vector<std::unique_ptr<Subscriber>> subs;
  for (int i = 0; i < n_clients; ++i) {
    int fd = -1;
    while ((fd = Connect(socket_path)) < 0 && elapsed_s() < warmup_timeout_s) {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    if (fd < 0) {
      std::fprintf(stderr, "daemon_load: nobody listens on %s\n", socket_path.c_str());
      return 1;
    }
    if (!SendAll(fd, "{\"cmd\":\"watch\",\"events\":false,\"corrected\":true}\n")) {
      std::fprintf(stderr, "daemon_load: cannot send the watch request\n");
      return 1;
    }
    subs.push_back(std::make_unique<Subscriber>(i, fd, &measuring, &stop));
    subs.back()->Start();
  }
  auto stop_all = [&] {
    stop = true;
    for (auto& s : subs) s->Join();
  };
  // Warm-up: every subscriber receives corrected samples of every device (without subscribers:
  // every device streams).
  while (n_clients == 0) {
    const json status = Request(socket_path, "status", "STATUS");
    int streaming = 0;
    if (status.is_object()) {
      for (const auto& [name, d] : status["devices"].items()) {
        streaming +=
            d.value("state", "") == "streaming" && d["counters"].value("samples", 0ULL) > 0;
      }
    }
    if (streaming >= n_devices) break;
    if (elapsed_s() > warmup_timeout_s) {
      std::fprintf(stderr, "daemon_load: %d of %d devices streaming after %.0f s\n", streaming,
                   n_devices, warmup_timeout_s);
      return 1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  while (n_clients > 0) {
    bool ready = true;
    std::string missing;
    for (auto& s : subs) {
      const auto c = s->counters();
      if (c.closed) {
        std::fprintf(stderr, "daemon_load: subscriber %d was closed by turncald during warm-up\n",
                     s->index());
        stop_all();
        return 1;
      }
      if (static_cast<int>(c.devices.size()) < n_devices) {
        ready = false;
        missing = std::to_string(c.devices.size()) + " of " + std::to_string(n_devices);
      }
    }
    if (ready) break;
    if (elapsed_s() > warmup_timeout_s) {
      std::fprintf(stderr,
                   "daemon_load: no corrected output from every device after %.0f s (%s devices "
                   "seen); status: %s\n",
                   warmup_timeout_s, missing.c_str(),
                   Request(socket_path, "status", "STATUS").dump().c_str());
      stop_all();
      return 1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  std::printf("daemon_load: corrected output from %d devices on %d subscribers after %.1f s\n",
              n_devices, n_clients, elapsed_s());  // (the script waits for this line)
  std::this_thread::sleep_for(std::chrono::duration<double>(settle_s));

  // The measurement.
  const json status_before = Request(socket_path, "status", "STATUS");
  const Snapshot first = Take(daemon_pid, sim_pid);
  measuring = true;
  std::vector<Row> rows;
  std::vector<Histogram> previous(subs.size());
  Snapshot last = first;
  std::vector<double> rss_t, rss_mb;
  if (first.daemon.ok) {
    rss_t.push_back(0);
    rss_mb.push_back(first.daemon.rss_mb);
  }
  Histogram quiet;
  double kworker_total_s = 0;
  int quiet_intervals = 0;
  double quiet_wall = 0, quiet_daemon_cpu_s = 0;
  std::printf("%7s %8s %7s %6s %6s %6s %6s %6s %6s %6s %8s %8s %8s %7s\n", "t_s", "daemon%",
              "rss_MB", "sim%", "subs%", "kwork%", "busy%", "other%", "steal%", "load1", "lines/s",
              "p99_ms", "p99.9_ms", "dropped");
  std::fflush(stdout);
  const std::int64_t end_ns = first.t_ns + static_cast<std::int64_t>(seconds * 1e9);
  std::uint64_t dropped_before = 0, lines_before = 0;
  for (std::int64_t next = first.t_ns; next < end_ns;) {
    next = std::min(end_ns, next + static_cast<std::int64_t>(interval_s * 1e9));
    while (MonotonicNs() < next) {
      std::this_thread::sleep_for(
          std::chrono::nanoseconds(std::min<std::int64_t>(next - MonotonicNs(), 100'000'000)));
    }
    const Snapshot now = Take(daemon_pid, sim_pid);
    const double wall = static_cast<double>(now.t_ns - last.t_ns) / 1e9;
    Histogram interval;
    std::uint64_t dropped = 0, lines = 0;
    for (std::size_t i = 0; i < subs.size(); ++i) {
      Histogram h = subs[i]->Snapshot();
      interval.Merge(h.Minus(previous[i]));
      previous[i] = std::move(h);
      const auto c = subs[i]->counters();
      dropped += c.dropped;
      lines += c.corrected;
    }
    Row r;
    r.t_s = static_cast<double>(now.t_ns - first.t_ns) / 1e9;
    r.daemon_cpu = Percent(last.daemon, now.daemon, wall);
    r.daemon_rss = now.daemon.ok ? now.daemon.rss_mb : -1;
    r.sim_cpu = Percent(last.sim, now.sim, wall);
    r.self_cpu = Percent(last.self, now.self, wall);
    const double total = now.system.total_s - last.system.total_s;
    r.busy = total > 0 ? 100.0 * (now.system.busy_s - last.system.busy_s) / total * ncpu : 0;
    r.load1 = now.system.load1;
    r.kworker = 100.0 * KworkerDelta(last.system.kworker_s, now.system.kworker_s) / wall;
    kworker_total_s += r.kworker / 100.0 * wall;
    r.steal = total > 0 ? 100.0 * (now.system.steal_s - last.system.steal_s) / total * ncpu : 0;
    r.other = r.busy - std::max(0.0, r.daemon_cpu) - std::max(0.0, r.sim_cpu) -
              std::max(0.0, r.self_cpu) - std::max(0.0, r.kworker);
    r.quiet = r.other < quiet_other && r.steal < quiet_steal;
    if (r.quiet) {
      quiet.Merge(interval);
      ++quiet_intervals;
      quiet_wall += wall;
      quiet_daemon_cpu_s += std::max(0.0, r.daemon_cpu) / 100.0 * wall;
    }
    r.lines = lines - lines_before;
    r.p99_ms = interval.Quantile(0.99);
    r.p999_ms = interval.Quantile(0.999);
    r.dropped = dropped - dropped_before;
    dropped_before = dropped;
    lines_before = lines;
    rows.push_back(r);
    if (now.daemon.ok) {
      rss_t.push_back(r.t_s);
      rss_mb.push_back(now.daemon.rss_mb);
    }
    std::printf(
        "%7.1f %8.2f %7.1f %6.2f %6.2f %6.2f %6.1f %6.1f %6.1f %6.2f %8.0f %8.3f %8.3f %7llu%s\n",
        r.t_s, r.daemon_cpu, r.daemon_rss, r.sim_cpu, r.self_cpu, r.kworker, r.busy, r.other,
        r.steal, r.load1, static_cast<double>(r.lines) / wall, r.p99_ms, r.p999_ms,
        static_cast<unsigned long long>(r.dropped), r.quiet ? "" : "  (disturbed)");
    std::fflush(stdout);
    last = now;
  }
  measuring = false;
  const Snapshot final_snapshot = last;
  const json status_after = Request(socket_path, "status", "STATUS");
  bool lost_subscriber = false;
  Histogram all;
  json clients = json::array();
  std::uint64_t corrected = 0, dropped = 0;
  for (auto& s : subs) {
    const Histogram h = s->Snapshot();
    const auto c = s->counters();
    lost_subscriber = lost_subscriber || c.closed;
    all.Merge(h);
    corrected += c.corrected;
    dropped += c.dropped;
    clients.push_back({{"corrected", c.corrected},
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
  stop_all();

  const double wall = static_cast<double>(final_snapshot.t_ns - first.t_ns) / 1e9;
  const double daemon_cpu = Percent(first.daemon, final_snapshot.daemon, wall);
  const double sim_cpu = Percent(first.sim, final_snapshot.sim, wall);
  const double self_cpu = Percent(first.self, final_snapshot.self, wall);
  const double kworker_cpu = 100.0 * kworker_total_s / wall;
  const double total = final_snapshot.system.total_s - first.system.total_s;
  const double busy =
      total > 0 ? 100.0 * (final_snapshot.system.busy_s - first.system.busy_s) / total * ncpu : 0;
  const double steal =
      total > 0 ? 100.0 * (final_snapshot.system.steal_s - first.system.steal_s) / total * ncpu : 0;
  double cpu_max = 0, rss_max = 0, busy_max = 0, load_max = 0;
  for (const Row& r : rows) {
    cpu_max = std::max(cpu_max, r.daemon_cpu);
    rss_max = std::max(rss_max, r.daemon_rss);
    busy_max = std::max(busy_max, r.busy);
    load_max = std::max(load_max, r.load1);
  }
  // Devices: samples decoded and lost during the window (the daemon's own counters).
  json devices = json::object();
  const json before = DeviceCounters(status_before), after = DeviceCounters(status_after);
  double samples_per_s = 0;
  std::uint64_t lost = 0, bad = 0;
  for (const auto& item : after.items()) {
    const std::string& name = item.key();
    const json& a = item.value();
    const json b = before.value(name, json::object());
    const auto delta = [&](const char* key) { return a.value(key, 0ULL) - b.value(key, 0ULL); };
    devices[name] = {{"samples", delta("samples")},
                     {"lost_samples", delta("lost_samples")},
                     {"bad_checksums", delta("bad_checksums")},
                     {"skipped_bytes", delta("skipped_bytes")},
                     {"state", a.value("state", "")}};
    samples_per_s += static_cast<double>(delta("samples")) / wall;
    lost += delta("lost_samples");
    bad += delta("bad_checksums");
  }
  const double expected = static_cast<double>(n_devices) * rate_hz * wall * n_clients;
  const double rss_slope = Slope(rss_t, rss_mb) * 60.0;  // MB per minute
  const double p99 = all.Quantile(0.99);

  const json result = {
      {"class", "LOAD_RESULT"},
      {"seconds", wall},
      {"devices", n_devices},
      {"rate_hz", rate_hz},
      {"clients", n_clients},
      {"daemon_cpu_pct", daemon_cpu},
      {"daemon_cpu_pct_max_interval", cpu_max},
      {"sim_cpu_pct", sim_cpu},
      {"subscribers_cpu_pct", self_cpu},
      {"kworker_cpu_pct", kworker_cpu},
      {"machine_busy_pct_of_one_core", busy},
      {"machine_busy_pct_max_interval", busy_max},
      {"steal_pct_of_one_core", steal},
      {"load1_max", load_max},
      {"latency_ms",
       {{"count", all.count()},
        {"mean", all.mean_ms()},
        {"p50", all.Quantile(0.5)},
        {"p90", all.Quantile(0.9)},
        {"p99", p99},
        {"p999", all.Quantile(0.999)},
        {"max", all.max_ms()},
        {"above_2ms_fraction", all.FractionAbove(2.0)},
        {"negative", all.negative()}}},
      {"undisturbed",
       {{"other_below_pct", quiet_other},
        {"steal_below_pct", quiet_steal},
        {"intervals", quiet_intervals},
        {"of", rows.size()},
        {"daemon_cpu_pct", quiet_wall > 0 ? 100.0 * quiet_daemon_cpu_s / quiet_wall : -1.0},
        {"latency_ms",
         {{"count", quiet.count()},
          {"p50", quiet.Quantile(0.5)},
          {"p90", quiet.Quantile(0.9)},
          {"p99", quiet.Quantile(0.99)},
          {"p999", quiet.Quantile(0.999)},
          {"above_2ms_fraction", quiet.FractionAbove(2.0)}}}}},
      {"corrected_lines", corrected},
      {"corrected_lines_expected", expected},
      {"dropped", dropped},
      {"daemon_samples_per_s", samples_per_s},
      {"lost_samples", lost},
      {"bad_checksums", bad},
      {"rss_mb",
       {{"start", rss_mb.empty() ? -1 : rss_mb.front()},
        {"max", rss_max},
        {"end", rss_mb.empty() ? -1 : rss_mb.back()},
        {"hwm", final_snapshot.daemon.hwm_mb},
        {"slope_mb_per_min", rss_slope}}},
      // The daemon's own timing: the loop's longest turn with a captured pose (loop_ms) and the
      // solve worker's longest pose update (solve_ms), when it reports them.
      {"loop_ms", status_after.is_object() ? status_after.value("loop_ms", json()) : json()},
      {"solve_ms", status_after.is_object() ? status_after.value("solve_ms", json()) : json()},
      {"per_client", clients},
      {"per_device", devices},
      {"intervals", [&] {
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
       }()}};

  auto verdict = [](bool ok) { return ok ? "meets" : "MISSES"; };
  std::printf(
      "\nturncald under load: %d devices x %.0f Hz, %d subscribers to corrected output, "
      "%.1f s\n",
      n_devices, rate_hz, n_clients, wall);
  std::printf(
      "  daemon CPU        %6.2f %% of one core (max interval %.2f %%)   target <= 10 %%: %s\n",
      daemon_cpu, cpu_max, verdict(daemon_cpu >= 0 && daemon_cpu <= 10.0));
  std::printf(
      "  latency           p50 %.3f  p90 %.3f  p99 %.3f  p99.9 %.3f  max %.3f ms "
      "(%llu lines, %.4f %% > 2 ms)   target p99 <= 2 ms: %s\n",
      all.Quantile(0.5), all.Quantile(0.9), p99, all.Quantile(0.999), all.max_ms(),
      static_cast<unsigned long long>(all.count()), 100.0 * all.FractionAbove(2.0),
      verdict(all.count() > 0 && p99 <= 2.0));
  std::printf(
      "  daemon RSS        start %.1f  max %.1f  end %.1f MB, slope %+.3f MB/min, "
      "VmHWM %.1f MB   target <= 50 MB, flat: %s\n",
      rss_mb.empty() ? -1.0 : rss_mb.front(), rss_max, rss_mb.empty() ? -1.0 : rss_mb.back(),
      rss_slope, final_snapshot.daemon.hwm_mb, verdict(rss_max > 0 && rss_max <= 50.0));
  std::printf(
      "  delivered         %llu corrected lines of %.0f expected (%.2f %%), %llu dropped; "
      "daemon decoded %.0f samples/s, %llu lost, %llu bad checksums\n",
      static_cast<unsigned long long>(corrected), expected,
      expected > 0 ? 100.0 * static_cast<double>(corrected) / expected : 0.0,
      static_cast<unsigned long long>(dropped), samples_per_s,
      static_cast<unsigned long long>(lost), static_cast<unsigned long long>(bad));
  std::printf(
      "  other processes   simulator %.2f %%, subscribers (this tool) %.2f %%, kernel "
      "workers %.2f %%; machine busy %.1f %% of one core (of %u), hypervisor steal %.1f %%, load1 "
      "max %.2f\n",
      sim_cpu, self_cpu, kworker_cpu, busy, std::thread::hardware_concurrency(), steal, load_max);
  std::printf(
      "  undisturbed       %d of %zu intervals with the rest of the machine below %.0f %% "
      "of a core and steal below %.0f %%: daemon CPU %.2f %%, latency p50 %.3f  p90 %.3f  p99 %.3f "
      " p99.9 %.3f ms "
      "(%llu lines)\n",
      quiet_intervals, rows.size(), quiet_other, quiet_steal,
      quiet_wall > 0 ? 100.0 * quiet_daemon_cpu_s / quiet_wall : -1.0, quiet.Quantile(0.5),
      quiet.Quantile(0.9), quiet.Quantile(0.99), quiet.Quantile(0.999),
      static_cast<unsigned long long>(quiet.count()));
  if (status_after.is_object()) {
    std::printf("  daemon status     loop_ms %s, solve_ms %s\n",
                status_after.value("loop_ms", json()).dump().c_str(),
                status_after.value("solve_ms", json()).dump().c_str());
  }
  std::printf("%s\n", result.dump().c_str());
  if (!json_out.empty()) std::ofstream(json_out) << result.dump(2) << "\n";
  if (lost_subscriber || (n_clients > 0 && all.count() == 0)) {
    std::fprintf(stderr, "daemon_load: %s\n",
                 lost_subscriber ? "a subscriber was closed during the measurement"
                                 : "no corrected line was measured");
    return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string mode = argc > 1 ? argv[1] : "";
  Args args;
  if ((mode != "seed" && mode != "measure") || !ParseArgs(argc, argv, 2, &args)) {
    std::fprintf(stderr,
                 "usage: daemon_load seed --truth TRUTH.json --state-dir DIR [--prefix imu]\n"
                 "       daemon_load measure --socket PATH --seconds N [--clients 4] "
                 "[--devices 8] [--rate 1000]\n"
                 "                   [--interval 10] [--daemon-pid P] [--sim-pid P] "
                 "[--warmup-timeout 180] [--settle 2] [--quiet-other 25]\n"
                 "                   [--quiet-steal 10] [--json-out FILE]\n"
                 "(tests/bench/daemon_load.sh sets everything up; docs/PERFORMANCE.md)\n");
    return 2;
  }
  return mode == "seed" ? Seed(args) : Measure(args);
}
