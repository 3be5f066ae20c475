#include "core/sequencing/free_intervals.h"

#include <fmt/format.h>

namespace turncal {

FreeIntervalCollector::FreeIntervalCollector(const SequencerOptions& options)
    : sequencer_(options, [this](const SequencerEvent& e) {
        switch (e.kind) {
          case SequencerEventKind::kCaptured:
            if (e.record) out_.intervals.push_back(*e.record);
            break;
          case SequencerEventKind::kSegmentSkipped:
            ++out_.skipped;
            out_.skip_reasons.push_back(fmt::format("at {:.2f} s: {}", e.t_s, e.reason));
            break;
          case SequencerEventKind::kNoiseRetry:
            ++out_.noise_retries;
            out_.last_noise_failure = e.reason;
            break;
          case SequencerEventKind::kScheduleEnd:
            out_.summary = e.reason;
            break;
          default:
            break;
        }
      }) {
  std::string error;
  sequencer_.SetFree(&error);  // a fresh sequencer is idle: cannot fail
}

FreeIntervals FreeIntervalCollector::Finish(std::int64_t now_ns) {
  sequencer_.Finish(now_ns);
  if (const NoiseProfile* p = sequencer_.noise()) out_.noise = *p;
  out_.totals = sequencer_.totals();
  return std::move(out_);
}

}  // namespace turncal
