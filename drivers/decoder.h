#pragma once
// The one small interface every protocol's scanner + decoder implements (issue "Device
// drivers"): push received bytes with their host receive time; frames and samples come out
// through a sink; counters account for every byte.
//
// A decoder keeps at most two maximal frames of unconsumed bytes, in a buffer it allocates once,
// so the steady state allocates nothing. Bytes are in exactly one of: an accepted frame
// (bytes_in_frames), skipped (bytes_skipped: noise, bad checksums, bad structure, timeouts), or
// still pending (pending_bytes(), waiting for the rest of a frame).

#include <cstdint>
#include <span>
#include <string>

#include "core/sequencing/sample.h"
#include "drivers/device_spec.h"

namespace turncal::drivers {

struct DecoderCounters {
  std::uint64_t bytes_in = 0;
  std::uint64_t bytes_in_frames = 0;
  std::uint64_t bytes_skipped = 0;
  std::uint64_t frames = 0;          // accepted (checksum and structure good)
  std::uint64_t samples = 0;         // emitted
  std::uint64_t bad_checksums = 0;   // candidates whose checksum failed
  std::uint64_t bad_structure = 0;   // checksum good, content malformed (rejected)
  std::uint64_t timeouts = 0;        // incomplete candidates dropped after the timeout
  std::uint64_t lost_samples = 0;    // by gaps of the device's counter
  std::uint64_t unknown_fields = 0;  // fields/items skipped because the decoder does not know them
};

// An accepted frame, valid only during the callback.
struct FrameView {
  Protocol protocol = Protocol::kMip;
  std::span<const std::uint8_t> bytes;  // the whole frame, sync to checksum
  std::int64_t t_host_ns = 0;           // receive time of the chunk that completed it
  std::uint8_t kind = 0;                // MIP descriptor set, Xbus MID, GX2 command byte
  bool carries_sample = false;          // the frame contributed to a Sample
};

class DecoderSink {
 public:
  virtual ~DecoderSink() = default;
  virtual void OnFrame(const FrameView& frame) = 0;
  virtual void OnSample(const Sample& sample) = 0;
};

class Decoder {
 public:
  virtual ~Decoder() = default;
  virtual Protocol protocol() const = 0;
  // Feeds received bytes; frames and samples they complete are passed to the sink now.
  virtual void Push(std::span<const std::uint8_t> bytes, std::int64_t t_host_ns) = 0;
  // Drops an incomplete frame whose first byte arrived more than the protocol's timeout before
  // `now_ns` (a corrupted length byte must not stall the stream) and releases a sample waiting
  // for more of its parts. For a link known to be quiet (a simulated clock): turncald does not call
  // it, because a loop that is late to read would drop frames whose rest waits unread in the
  // kernel, and a replay could not know when the live loop had looked. A stale candidate does no
  // harm anyway: when bytes come again its checksum fails and the bytes inside it are rescanned.
  virtual void CheckTimeout(std::int64_t now_ns) = 0;
  // End of input: rescans the pending bytes one start position at a time (frames inside an
  // incomplete false candidate are recovered), counts what is left as skipped, and emits a
  // waiting sample.
  virtual void Finish() = 0;
  virtual const DecoderCounters& counters() const = 0;
  virtual std::size_t pending_bytes() const = 0;
};

}  // namespace turncal::drivers
