#pragma once
// One request/reply exchange over a ByteLink with a protocol's own decoder: send, then read and
// decode until a frame the caller accepts arrives, skipping everything else (streaming data keeps
// coming while a device is being configured), with a deadline and retries.

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "drivers/byte_link.h"
#include "drivers/decoder.h"

namespace turncal::drivers {

struct ExchangeOptions {
  std::chrono::milliseconds reply_timeout{300};
  int attempts = 3;  // the request is sent again when no reply came in time
};

struct ExchangeResult {
  bool ok = false;
  std::string error;
  std::vector<std::uint8_t> reply;  // the accepted frame
  int attempts = 0;
  int skipped_frames = 0;  // frames that were not the reply (streaming data, other replies)
};

// `make_decoder(sink)` builds the protocol's decoder; `accept(frame)` returns true for the reply.
ExchangeResult Exchange(ByteLink* link, std::span<const std::uint8_t> request,
                        const std::function<std::unique_ptr<Decoder>(DecoderSink*)>& make_decoder,
                        const std::function<bool(std::span<const std::uint8_t>)>& accept,
                        const ExchangeOptions& options, const std::string& what);

}  // namespace turncal::drivers
