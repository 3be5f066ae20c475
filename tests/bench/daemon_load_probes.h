// What tests/bench/daemon_load.cc measures with: the monotonic clock, --key value arguments, CPU
// and memory from /proc (of a process, of the machine, of the kernel's workers), requests on
// turncald's socket, and a snapshot of all of them at one moment.
#pragma once

#include <cstdint>
#include <cstdlib>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace daemon_load {

using nlohmann::json;

std::int64_t MonotonicNs();

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

bool ParseArgs(int argc, char** argv, int first, Args* args);

// /proc
struct ProcSample {
  bool ok = false;
  double cpu_s = 0;  // utime + stime
  double rss_mb = 0;
  double hwm_mb = 0;
};

// A process's CPU and memory; `pid` may be "self".
ProcSample ReadProc(const std::string& pid);

struct SystemSample {
  double busy_s = 0, total_s = 0, steal_s = 0;  // busy: user, nice, system, irq, softirq
  double load1 = 0;
  std::map<std::string, double> kworker_s;  // kernel workers (the tty layer moves pty bytes)
};

// The machine's CPU counters and load, and every kworker's CPU time.
SystemSample ReadSystem();

// Seconds the kworkers of `now` ran since `before` (new ones: all of their time).
double KworkerDelta(const std::map<std::string, double>& before,
                    const std::map<std::string, double>& now);

// Sockets: a connection to a Unix socket (-1 when nobody listens), a whole write, and one request
// on its own connection: the reply of the given class (or null).
int Connect(const std::string& path);
bool SendAll(int fd, const std::string& text);
json Request(const std::string& path, const std::string& cmd, const std::string& reply_class);

// The daemon, the simulator and this process (and the machine) at one moment.
struct Snapshot {
  std::int64_t t_ns = 0;
  ProcSample daemon, sim, self;
  SystemSample system;
};

Snapshot Take(const std::string& daemon_pid, const std::string& sim_pid);

// CPU between two samples of a process, in % of one core (-1 when either is missing).
double Percent(const ProcSample& a, const ProcSample& b, double wall_s);

// Least-squares slope of y over x.
double Slope(const std::vector<double>& x, const std::vector<double>& y);

// The counters, state and rate of every device in a STATUS reply.
json DeviceCounters(const json& status);

}  // namespace daemon_load
