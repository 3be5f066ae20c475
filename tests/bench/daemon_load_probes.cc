// tests/bench/daemon_load_probes.h: the clock, arguments, /proc, sockets.
#include "daemon_load_probes.h"

#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace daemon_load {

std::int64_t MonotonicNs() {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

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

namespace {

long ClockTicks() {
  static const long ticks = ::sysconf(_SC_CLK_TCK);
  return ticks;
}

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

}  // namespace

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

}  // namespace daemon_load
