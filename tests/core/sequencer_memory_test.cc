// Memory per pose is constant in the dwell length (issue "Position sequencer"): the heap
// allocations made while a pose collects are counted (global operator new) for a 5 s and a 500 s
// dwell; they must be the same number, the same size up to the digits of the counts in the
// events' text (no sample buffers).

// GCC sees the counting operator delete inlined into gtest's allocations and cannot tell that
// operator new is malloc here too.
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"

#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <new>
#include <random>

#include "core/sequencing/sequencer.h"

namespace {
std::atomic<long long> g_allocations{0};
std::atomic<long long> g_bytes{0};
}  // namespace

void* operator new(std::size_t n) {
  ++g_allocations;
  g_bytes += static_cast<long long>(n);
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

namespace turncal {
namespace {

struct Measured {
  long long allocations = 0, bytes = 0;
  std::int64_t used = 0;
};

Measured CollectOnePose(double dwell_s) {
  const double rate = 200;
  SequencerOptions o;
  o.dwell_s = dwell_s;
  o.still_timeout_s = 10;
  bool collecting = false, captured = false;
  std::int64_t used = 0;
  Sequencer seq(o, [&](const SequencerEvent& e) {
    if (e.kind == SequencerEventKind::kCollecting) collecting = true;
    if (e.kind == SequencerEventKind::kCaptured) {
      captured = true;
      used = e.record->acc->count;
    }
  });
  std::mt19937_64 rng(1);
  std::normal_distribution<double> n(0, 1);
  Sample s;
  s.acc_mps2 = Eigen::Vector3d::Zero();
  s.gyr_radps = Eigen::Vector3d::Zero();
  s.mag = Eigen::Vector3d::Zero();
  Measured m;
  long long a0 = 0, b0 = 0;
  bool counting = false;
  for (std::int64_t k = 0; !captured && k < static_cast<std::int64_t>((dwell_s + 20) * rate); ++k) {
    const double t = static_cast<double>(k) / rate;
    if (k == static_cast<std::int64_t>(3 * rate)) {
      Announcement a;
      a.index = 0;
      a.t_host_ns = static_cast<std::int64_t>(t * 1e9);
      std::string error;
      EXPECT_TRUE(seq.Announce(a, &error));
    }
    s.t_host_ns = static_cast<std::int64_t>(t * 1e9);
    s.t_device_s = t;
    s.counter = static_cast<std::uint32_t>(k);
    *s.acc_mps2 = Eigen::Vector3d(0.01 * n(rng), 0.01 * n(rng), -9.8 + 0.01 * n(rng));
    *s.gyr_radps = Eigen::Vector3d(1e-3 * n(rng), 1e-3 * n(rng), 1e-3 * n(rng));
    *s.mag = Eigen::Vector3d(0.2 + 1e-3 * n(rng), 1e-3 * n(rng), 0.4 + 1e-3 * n(rng));
    if (collecting && !counting) {
      counting = true;
      a0 = g_allocations;
      b0 = g_bytes;
    }
    seq.Push(s);
  }
  EXPECT_TRUE(captured);
  m.allocations = g_allocations - a0;
  m.bytes = g_bytes - b0;
  m.used = used;
  return m;
}

TEST(SequencerMemory, ConstantInTheDwellLength) {
  const Measured short_dwell = CollectOnePose(5);
  const Measured long_dwell = CollectOnePose(500);
  EXPECT_EQ(short_dwell.used, 1000);
  EXPECT_EQ(long_dwell.used, 100000);
  EXPECT_EQ(short_dwell.allocations, long_dwell.allocations);
  // The captured event's text carries the sample count and duration: a few more digits.
  EXPECT_LE(std::abs(short_dwell.bytes - long_dwell.bytes), 16);
  RecordProperty("allocations_per_pose", std::to_string(long_dwell.allocations));
  RecordProperty("bytes_per_pose", std::to_string(long_dwell.bytes));
  std::printf("one pose: %lld allocations, %lld bytes, for 1000 and for 100000 samples\n",
              long_dwell.allocations, long_dwell.bytes);
}

}  // namespace
}  // namespace turncal
