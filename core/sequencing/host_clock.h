#pragma once
// When a sample left its device, on the host's clock. A sample's host time is when the daemon
// read it: a daemon (or simulator, or kernel) that stalls reads a backlog at once, and samples
// sent before a pose announcement are then read after it. The sequencer takes "samples after
// the announcement", so a backlog of the previous pose's still samples became the next pose's
// record (2026-11-22: imu2 pose 3 from "300 samples over 0.01 s", normalised residual 2 134).
//
// The device's clock says when each sample was sent. The host time of sending is the device time
// (in host seconds) plus an offset; every read is later than the send, so the smallest offset
// seen (t_host - t_device) is the best estimate of the offset, and one sample read promptly is
// enough. The two clocks drift apart (a crystal: < 100 ppm); an old minimum ages by max_drift
// (1000 ppm) per second, so the estimate follows drift either way, and a backlog of 15 s is
// still mapped within 15 ms. Mapped times never exceed the read time and never go backwards.
//
// The rate. A device clock need not keep real time: the simulator runs a session N times faster
// than real time (its device clocks too), and a timer whose tick the driver has wrong runs at
// another rate. The rate (host seconds per device second) is measured from the stream: the
// sample with the smallest offset in each 0.25 s of host time (one prompt read in that stretch
// is enough) over the last 32 s; the median of the slopes between those points at least 2 s
// apart (Theil-Sen: stretches without a prompt read do not move it). A rate within 1 % of 1 is
// real time (the rest is drift, which the ageing covers); another rate is used once measured
// (3.25 s after the stream starts at the earliest), and until then a sample is mapped as without
// this mapping (at worst, its read time). Fixed storage: nothing is allocated per sample.
//
// A device clock that goes backwards, or forward by more than the host's clock did plus 1 s, is
// a reset (a replug, a wrap, a corrupted time stamp): the estimate starts again from that
// sample, so at worst a sample is mapped to its read time, as without this mapping. A sample
// without a device time is mapped to its read time. Pure computation.

#include <cstdint>
#include <optional>
#include <vector>

namespace turncal {

class HostClock {
 public:
  explicit HostClock(double max_drift = 1e-3);

  // The host time (ns) at which the sample read at t_host_ns was sent.
  std::int64_t Map(std::int64_t t_host_ns, std::optional<double> t_device_s);

  std::uint64_t resets() const { return resets_; }
  // Host seconds per device second: 1 until another rate has been measured.
  double rate() const { return rate_; }

 private:
  struct Point {
    double device_s;
    std::int64_t host_ns;
  };
  void MeasureRate(const Point& p);
  double Key(const Point& p) const;

  double max_drift_;
  double rate_ = 1.0;
  // min over samples of (t_host - rate * t_device) - max_drift * rate * t_device, in seconds
  // relative to the first sample of the epoch (doubles keep 0.1 ns over days).
  std::optional<double> key_min_;
  Point min_point_{};  // the sample it came from
  std::int64_t epoch_host_ns_ = 0;
  double epoch_device_s_ = 0;
  std::optional<double> last_device_s_;
  std::int64_t last_host_ns_ = 0;
  std::optional<std::int64_t> last_mapped_ns_;
  std::uint64_t resets_ = 0;
  // The rate measurement: the smallest-offset sample of each closed 0.25 s stretch, and of the
  // open one.
  static constexpr std::size_t kMaxStretches = 130;  // 32 s of 0.25 s stretches, and the open one
  std::vector<Point> stretches_;                     // a ring of kMaxStretches
  std::size_t stretch_first_ = 0, stretch_count_ = 0;
  std::vector<double> slopes_;  // scratch, reserved for every pair
  std::optional<Point> open_;
  std::int64_t open_start_ns_ = 0;
};

}  // namespace turncal
