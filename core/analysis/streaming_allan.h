#pragma once
// The overlapping Allan variance and the overlapping Hadamard variance of several channels,
// computed as the samples arrive (issue 39 item 1), with memory that does not grow with the
// recording (IEEE Std 952-2020 Annex C; Riley, NIST SP 1065, the overlapping estimators).
//
// For a cluster of m samples, with S the running sum of the (centred) samples,
//   Allan     sigma^2(m) = sum_k (S[k+2m] - 2 S[k+m] + S[k])^2 / (2 m^2 terms)
//   Hadamard  H^2(m)     = sum_k (S[k+3m] - 3 S[k+2m] + 3 S[k+m] - S[k])^2 / (6 m^2 terms)
// over the starting points k. Cluster sizes below 2R (R = `exact_clusters`) use every starting
// point: the fully overlapping estimator. A larger cluster size m is rounded to a multiple of
// the largest power of two d = 2^L with m / d >= R, and its starting points are every d samples
// (the running sum is kept every d samples for the last 6R of them): the estimator differs from
// the fully overlapping one by starting points d <= m / R apart. Memory: about 6R values and a
// block per channel for each power of two up to the longest cluster, well under a MB for any
// recording; time: every cluster size below 2R per sample, a few more every 2^L samples, summed
// a block at a time with vector arithmetic.
//
// The times are not looked at: the caller gives the sample period when it reads the points.
// Pure computation.

#include <cstddef>
#include <cstdint>
#include <vector>

namespace turncal {

struct StreamingAllanOptions {
  int per_decade = 10;  // cluster sizes per decade (log spaced, from one sample)
  // R above: a power of two, at least 16. At 32 the starting points of a long cluster are at
  // most m / 32 apart, which costs the estimator under 0.1 % of its degrees of freedom
  // (OverlappingEdf with and without the stride) and halves the time of R = 256.
  int exact_clusters = 32;
};

struct StreamingAllanPoint {
  std::int64_t m = 0;       // cluster size in samples
  std::int64_t stride = 1;  // samples between starting points (1: fully overlapping)
  // Per channel; empty when the recording is too short for the estimator at this m.
  std::vector<double> avar, hvar;
  std::int64_t avar_terms = 0, hvar_terms = 0;  // starting points summed
};

class StreamingAllan {
 public:
  explicit StreamingAllan(int channels, const StreamingAllanOptions& options = {});

  // One sample of every channel (`channels` values). Non-finite values must not be given.
  void Add(const double* x);

  std::int64_t samples() const { return n_; }
  int channels() const { return channels_; }
  // Every cluster size with at least one Allan term, in increasing m.
  std::vector<StreamingAllanPoint> Points() const;
  // What the estimator holds now (rings and sums), in bytes.
  std::size_t MemoryBytes() const;

 private:
  // Clusters of j blocks of 2^shift samples: the running sums at the block ends, each channel's
  // in one contiguous row of `capacity` (global block index `base` first, `filled` of them);
  // the terms summed up to block index `summed` (exclusive), a block of sums at a time with
  // vector arithmetic; then the oldest sums no term reaches back to are dropped.
  struct Level {
    int shift = 0;
    std::vector<std::int64_t> j;  // cluster sizes in blocks, increasing
    std::vector<double> sums;     // channels x capacity
    std::size_t capacity = 0;
    std::int64_t base = 0, filled = 0, summed = 0;
    std::vector<double> asum, hsum;  // per cluster size and channel
    std::vector<std::int64_t> aterms, hterms;
    double At(std::int64_t k, std::size_t channel) const {
      return sums[channel * capacity + static_cast<std::size_t>(k - base)];
    }
  };

  void MakeLevel(int shift);
  void Append(Level* level, const double* sum) const;
  void SumPending(Level* level) const;

  int channels_;
  StreamingAllanOptions options_;
  mutable std::vector<Level> levels_;  // mutable: Points() sums what is pending
  std::vector<double> x0_, sum_;       // the first sample (centring) and the running sum
  std::int64_t n_ = 0;
  std::vector<std::int64_t> grid_;  // the log-spaced cluster sizes (before rounding)
};

}  // namespace turncal
