#include "core/analysis/streaming_allan.h"

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstring>

namespace turncal {

namespace {

constexpr int kMaxLevels = 62;
// Sums summed at a time: level 0's every sample, the others' every 2^shift samples.
constexpr std::int64_t kBlockZero = 4096, kBlock = 1024;

}  // namespace

StreamingAllan::StreamingAllan(int channels, const StreamingAllanOptions& options)
    : channels_(std::max(channels, 1)), options_(options) {
  int r = 16;
  while (r < options_.exact_clusters) r *= 2;
  options_.exact_clusters = r;
  options_.per_decade = std::max(options_.per_decade, 1);
  for (int i = 0;; ++i) {
    const double m = std::pow(10.0, static_cast<double>(i) / options_.per_decade);
    if (m > 1e15) break;
    const auto k = static_cast<std::int64_t>(std::llround(m));
    if (grid_.empty() || k > grid_.back()) grid_.push_back(k);
  }
  x0_.assign(static_cast<std::size_t>(channels_), 0.0);
  sum_.assign(static_cast<std::size_t>(channels_), 0.0);
  levels_.reserve(kMaxLevels);
  MakeLevel(0);
}

void StreamingAllan::MakeLevel(int shift) {
  Level level;
  level.shift = shift;
  const std::int64_t r = options_.exact_clusters;
  for (std::int64_t m : grid_) {
    std::int64_t j = 0;
    if (shift == 0) {
      if (m >= 2 * r) break;
      j = m;
    } else {
      j = static_cast<std::int64_t>(std::llround(std::ldexp(static_cast<double>(m), -shift)));
      if (j < r) continue;
      if (j >= 2 * r) break;
    }
    if (level.j.empty() || j > level.j.back()) level.j.push_back(j);
  }
  const std::size_t c = static_cast<std::size_t>(channels_);
  // The longest Hadamard term reaches 3 (2R - 1) blocks back: 6R sums kept, and a block.
  level.capacity = static_cast<std::size_t>(6 * r + (shift == 0 ? kBlockZero : kBlock));
  level.sums.assign(level.capacity * c, 0.0);
  level.asum.assign(level.j.size() * c, 0.0);
  level.hsum.assign(level.j.size() * c, 0.0);
  level.aterms.assign(level.j.size(), 0);
  level.hterms.assign(level.j.size(), 0);
  levels_.push_back(std::move(level));
  Level& made = levels_.back();
  if (shift == 0) {
    Append(&made, sum_.data());  // the running sum before the first sample: 0
    return;
  }
  // The level's block ends since the start are every other block end of the level below, which
  // still holds them all: this level is made when it has 2R blocks (4R of the level below, which
  // keeps more than 6R).
  const Level& below = levels_[static_cast<std::size_t>(shift - 1)];
  std::vector<double> sum(c);
  for (std::int64_t k = 0; k <= (n_ >> shift); ++k) {
    for (std::size_t i = 0; i < c; ++i) sum[i] = below.At(2 * k, i);
    Append(&made, sum.data());
  }
}

void StreamingAllan::Append(Level* level, const double* sum) const {
  const std::size_t c = static_cast<std::size_t>(channels_);
  if (static_cast<std::size_t>(level->filled) == level->capacity) {
    SumPending(level);
    const std::int64_t keep = 6 * options_.exact_clusters;
    for (std::size_t i = 0; i < c; ++i) {
      double* row = level->sums.data() + i * level->capacity;
      std::memmove(row, row + (level->filled - keep),
                   static_cast<std::size_t>(keep) * sizeof(double));
    }
    level->base += level->filled - keep;
    level->filled = keep;
  }
  const std::size_t at = static_cast<std::size_t>(level->filled);
  for (std::size_t i = 0; i < c; ++i) level->sums[i * level->capacity + at] = sum[i];
  ++level->filled;
}

void StreamingAllan::SumPending(Level* level) const {
  const std::int64_t end = level->base + level->filled;  // block index after the last sum
  if (level->summed >= end) return;
  const std::size_t c = static_cast<std::size_t>(channels_);
  for (std::size_t t = 0; t < level->j.size(); ++t) {
    const std::int64_t m = level->j[t];
    const std::int64_t a0 = std::max(level->summed, 2 * m);
    const std::int64_t h0 = std::max(level->summed, 3 * m);
    if (end <= a0) break;  // nor any longer cluster
    for (std::size_t i = 0; i < c; ++i) {
      const double* row = level->sums.data() + i * level->capacity;
      auto from = [&](std::int64_t k, std::int64_t first) {
        return Eigen::Map<const Eigen::ArrayXd>(row + (k - level->base), end - first);
      };
      level->asum[t * c + i] +=
          (from(a0, a0) - 2.0 * from(a0 - m, a0) + from(a0 - 2 * m, a0)).square().sum();
      if (end > h0) {
        level->hsum[t * c + i] +=
            (from(h0, h0) - 3.0 * (from(h0 - m, h0) - from(h0 - 2 * m, h0)) - from(h0 - 3 * m, h0))
                .square()
                .sum();
      }
    }
    level->aterms[t] += end - a0;
    if (end > h0) level->hterms[t] += end - h0;
  }
  level->summed = end;
}

void StreamingAllan::Add(const double* x) {
  const std::size_t c = static_cast<std::size_t>(channels_);
  if (n_ == 0) std::copy(x, x + c, x0_.begin());
  for (std::size_t i = 0; i < c; ++i) sum_[i] += x[i] - x0_[i];
  ++n_;
  const std::int64_t r = options_.exact_clusters;
  for (int shift = 0; shift < kMaxLevels; ++shift) {
    if ((n_ & ((std::int64_t{1} << shift) - 1)) != 0) break;
    if (static_cast<std::size_t>(shift) < levels_.size()) {
      Append(&levels_[static_cast<std::size_t>(shift)], sum_.data());
      continue;
    }
    // A level is made when its smallest cluster size (R blocks) first has an Allan term.
    if (n_ == (2 * r) << shift) MakeLevel(shift);
    break;
  }
}

std::vector<StreamingAllanPoint> StreamingAllan::Points() const {
  std::vector<StreamingAllanPoint> out;
  const std::size_t c = static_cast<std::size_t>(channels_);
  for (Level& level : levels_) {
    SumPending(&level);
    for (std::size_t t = 0; t < level.j.size(); ++t) {
      if (level.aterms[t] == 0) continue;
      StreamingAllanPoint p;
      p.m = level.j[t] << level.shift;
      p.stride = std::int64_t{1} << level.shift;
      const double m2 = static_cast<double>(p.m) * static_cast<double>(p.m);
      p.avar_terms = level.aterms[t];
      p.hvar_terms = level.hterms[t];
      for (std::size_t i = 0; i < c; ++i) {
        p.avar.push_back(level.asum[t * c + i] / (2.0 * m2 * static_cast<double>(p.avar_terms)));
        if (p.hvar_terms > 0) {
          p.hvar.push_back(level.hsum[t * c + i] / (6.0 * m2 * static_cast<double>(p.hvar_terms)));
        }
      }
      out.push_back(std::move(p));
    }
  }
  std::sort(out.begin(), out.end(), [](const auto& a, const auto& b) {
    return a.m != b.m ? a.m < b.m : a.stride < b.stride;
  });
  out.erase(
      std::unique(out.begin(), out.end(), [](const auto& a, const auto& b) { return a.m == b.m; }),
      out.end());
  return out;
}

std::size_t StreamingAllan::MemoryBytes() const {
  std::size_t bytes = sizeof(*this) + grid_.size() * sizeof(std::int64_t) +
                      (x0_.size() + sum_.size()) * sizeof(double);
  for (const Level& level : levels_) {
    bytes += sizeof(Level) +
             (level.sums.size() + level.asum.size() + level.hsum.size()) * sizeof(double) +
             (level.j.size() + level.aterms.size() + level.hterms.size()) * sizeof(std::int64_t);
  }
  return bytes;
}

}  // namespace turncal
