#pragma once
// The sample stream to the clients that watch (docs/protocol.md "watch"): for each sample, the
// SAMPLE line and the CORRECTED lines (protocol/sample_line.h) its watchers asked for, each shape
// built once and shared by every watcher that wants it, in buffers kept between samples (no
// allocation per sample: 8 devices at 1000 Hz); a watcher's rate limit; a slow client loses stream
// lines (counted), never the loop.

#include <memory>
#include <string>
#include <vector>

#include "core/sequencing/sample.h"
#include "daemon/service/socket_server.h"
#include "daemon/station/station.h"

namespace turncal::daemon {

class SampleStream {
 public:
  // `sample` as the device sent it (the raw lines), `station_sample` as the station sees it (the
  // corrected lines: the device's output re-expressed after a write into it).
  void Send(const SocketServer& server, const Station& station, int device, const Sample& sample,
            const Sample& station_sample);

 private:
  // Four shapes of corrected line: with or without raw, with or without sigma.
  std::string corrected_text_[4], raw_text_;
  // The watching sessions (a send may close a session, which leaves the server's map; the
  // references keep it alive until the sample is done).
  std::vector<std::shared_ptr<ClientSession>> watchers_;
};

}  // namespace turncal::daemon
