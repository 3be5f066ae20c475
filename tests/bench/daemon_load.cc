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
//
// The tool's parts: daemon_load_probes.h (clock, arguments, /proc, socket requests),
// daemon_load_subscriber.h (latency histogram, subscriber thread), daemon_load_measure.h (the
// measure mode's steps).
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "daemon_load_measure.h"
#include "daemon_load_probes.h"

namespace {

using daemon_load::Args;
using daemon_load::json;

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

}  // namespace

int main(int argc, char** argv) {
  const std::string mode = argc > 1 ? argv[1] : "";
  Args args;
  if ((mode != "seed" && mode != "measure") || !daemon_load::ParseArgs(argc, argv, 2, &args)) {
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
  return mode == "seed" ? Seed(args) : daemon_load::Measure(args);
}
