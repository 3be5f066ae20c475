#include "daemon/service/sample_stream.h"

#include "protocol/sample_line.h"

namespace turncal::daemon {

void SampleStream::Send(const SocketServer& server, const Station& station, int device,
                        const Sample& sample, const Sample& station_sample) {
  bool built[4] = {false, false, false, false}, raw_built = false;
  Station::Corrected c;
  bool have_correction = false, tried = false;
  watchers_.clear();
  for (const auto& [id, s] : server.sessions()) {
    if (s->watch && (s->watch->corrected || s->watch->raw)) watchers_.push_back(s);
  }
  for (const auto& s : watchers_) {
    const WatchSpec& w = *s->watch;
    if (!w.device.empty() && w.device != sample.device) continue;
    if (w.max_rate_hz > 0) {
      std::int64_t& last = s->last_sample_ns[sample.device];
      if (sample.t_host_ns - last < w.MinIntervalNs()) continue;
      last = sample.t_host_ns;
    }
    if (w.corrected) {
      if (!tried ||
          (w.uncertainty && !c.acc_sigma && !c.mag_sigma && !c.gyr_sigma && have_correction)) {
        have_correction = station.Correct(device, station_sample, &c, w.uncertainty);
        c.t_sensor_s = station.SensorTimeOf(device, station_sample);
        tried = true;
      }
      if (!have_correction) {
        if (!w.raw) continue;  // nothing to correct with yet; raw samples still go out
      } else {
        const int shape = (w.raw ? 1 : 0) + (w.uncertainty ? 2 : 0);
        std::string& text = corrected_text_[shape];
        if (!built[shape]) {
          built[shape] = true;
          text.clear();
          protocol::AppendCorrectedLine(&text, sample, c, w.raw, w.uncertainty);
        }
        s->Stream(text);
        continue;
      }
    }
    if (!raw_built) {
      raw_built = true;
      raw_text_.clear();
      protocol::AppendSampleLine(&raw_text_, sample);
    }
    s->Stream(raw_text_);
  }
  watchers_.clear();
}

}  // namespace turncal::daemon
