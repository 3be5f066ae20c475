#pragma once
// The static intervals of a tumble (issue 22, free mode): a Sequencer in free mode
// (Sequencer::SetFree) over a stream of samples, its records kept as the free models' intervals
// (core/modeling/free_model.h) and what it skipped counted with the reasons. The stillness
// thresholds come from the noise the sequencer measures over the stream's first still second (or
// the configured profile), not from a hand-set threshold. Pure computation.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/modeling/free_model.h"
#include "core/sequencing/sequencer.h"

namespace turncal {

struct FreeIntervals {
  std::vector<FreeInterval> intervals;
  std::int64_t skipped = 0;
  std::vector<std::string> skip_reasons;  // "at 170.3 s: ..." for each skipped still segment
  std::string summary;                    // the sequencer's closing line
  std::optional<NoiseProfile> noise;      // the profile the stillness tests used
  // Start-up noise measurements that failed (the stream was not still at first), and the last
  // one's reason: with no profile at all, no interval can be found.
  std::int64_t noise_retries = 0;
  std::string last_noise_failure;
  SampleCounts totals;
};

class FreeIntervalCollector {
 public:
  // `options` must be valid (SequencerOptions::IsValid).
  explicit FreeIntervalCollector(const SequencerOptions& options);
  void Push(const Sample& sample) { sequencer_.Push(sample); }
  // End of input: the last still segment is taken when long enough.
  FreeIntervals Finish(std::int64_t now_ns);
  const Sequencer& sequencer() const { return sequencer_; }

 private:
  FreeIntervals out_;
  Sequencer sequencer_;
};

}  // namespace turncal
