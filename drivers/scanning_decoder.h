#pragma once
// The byte-level machinery every protocol shares: a buffer (two maximal frames) allocated once, a
// scan loop that asks the protocol to examine the bytes at the current position, and the counters.
// A protocol derives from ScanningDecoder<Derived> and provides
//   Examination Examine(const std::uint8_t* p, std::size_t n);   // n >= 1
//   bool Accept(std::span<const std::uint8_t> frame, std::int64_t t_host_ns);  // false: malformed
//   void Release();  // emit a sample still waiting for parts (timeout, end of input)

#include <cstring>
#include <memory>

#include "drivers/decoder.h"

namespace turncal::drivers {

struct Examination {
  // kMalformed: a header no valid frame can have (e.g. a length over the protocol's cap).
  enum Verdict { kNeedMore, kGarbage, kBadChecksum, kMalformed, kFrame } verdict = kNeedMore;
  std::size_t length = 0;  // kGarbage: bytes to skip (>= 1); kFrame: frame length
};

template <class Derived>
class ScanningDecoder : public Decoder {
 public:
  // Bytes are scanned where they are (no copy) when nothing is pending; only a frame split
  // between two pushes is assembled in the buffer.
  void Push(std::span<const std::uint8_t> bytes, std::int64_t t_host_ns) override {
    counters_.bytes_in += bytes.size();
    while (!bytes.empty()) {
      if (size_ == 0) {
        const std::size_t used = ScanRange(bytes.data(), bytes.size(), t_host_ns);
        const std::size_t rest = bytes.size() - used;  // an incomplete candidate's bytes
        if (rest > capacity_) {
          // A candidate cannot need more than the buffer holds (Examine's contract); if one
          // does, its first byte is dropped rather than overflow anything.
          ++counters_.bad_structure;
          ++counters_.bytes_skipped;
          bytes = bytes.subspan(used + 1);
          continue;
        }
        std::memcpy(buffer_.get(), bytes.data() + used, rest);
        size_ = rest;
        pending_since_ns_ = t_host_ns;
        return;
      }
      // Complete the pending candidate with as many new bytes as the buffer takes.
      const std::size_t k = std::min(bytes.size(), capacity_ - size_);
      if (k == 0) {  // full and still incomplete: same as above
        ++counters_.bad_structure;
        Skip(1);
        ScanBuffer(t_host_ns);
        continue;
      }
      std::memcpy(buffer_.get() + size_, bytes.data(), k);
      size_ += k;
      const std::size_t used = ScanRange(buffer_.get(), size_, t_host_ns);
      const std::size_t rest = size_ - used;
      if (rest <= k) {
        // Everything that was pending is consumed; the rest is still in `bytes`.
        size_ = 0;
        bytes = bytes.subspan(k - rest);
      } else {
        std::memmove(buffer_.get(), buffer_.get() + used, rest);
        size_ = rest;
        if (used > 0) pending_since_ns_ = t_host_ns;
        bytes = bytes.subspan(k);
      }
    }
  }

  void CheckTimeout(std::int64_t now_ns) override {
    if (size_ > 0 && now_ns - pending_since_ns_ > timeout_ns_) {
      ++counters_.timeouts;
      Skip(1);
      pending_since_ns_ = now_ns;
      ScanBuffer(now_ns);
    }
    if (now_ns - last_frame_ns_ > timeout_ns_) static_cast<Derived*>(this)->Release();
  }

  void Finish() override {
    // Nothing more will come: a candidate still waiting for bytes is not a frame. Drop its first
    // byte and scan again, so frames inside a false candidate's claimed length are recovered.
    while (size_ > 0) {
      Skip(1);
      ScanBuffer(last_frame_ns_);
    }
    static_cast<Derived*>(this)->Release();
  }

  const DecoderCounters& counters() const override { return counters_; }
  std::size_t pending_bytes() const override { return size_; }

 protected:
  ScanningDecoder(std::size_t max_frame, std::int64_t timeout_ns, DecoderSink* sink)
      : sink_(sink),
        capacity_(2 * max_frame),
        buffer_(new std::uint8_t[2 * max_frame]),
        timeout_ns_(timeout_ns) {}

  DecoderCounters counters_;
  DecoderSink* sink_;

 private:
  void Skip(std::size_t n) {
    counters_.bytes_skipped += n;
    std::memmove(buffer_.get(), buffer_.get() + n, size_ - n);
    size_ -= n;
  }

  void ScanBuffer(std::int64_t t_host_ns) {
    const std::size_t used = ScanRange(buffer_.get(), size_, t_host_ns);
    if (used > 0) {
      std::memmove(buffer_.get(), buffer_.get() + used, size_ - used);
      size_ -= used;
    }
  }

  // Scans data[0, n) and returns how many bytes were consumed (frames and skipped bytes); the
  // rest is the start of an incomplete candidate.
  std::size_t ScanRange(const std::uint8_t* data, std::size_t n, std::int64_t t_host_ns) {
    Derived& self = *static_cast<Derived*>(this);
    std::size_t pos = 0;
    while (pos < n) {
      const Examination e = self.Examine(data + pos, n - pos);
      if (e.verdict == Examination::kNeedMore) break;
      if (e.verdict == Examination::kGarbage) {
        counters_.bytes_skipped += e.length;
        pos += e.length;
      } else if (e.verdict == Examination::kBadChecksum || e.verdict == Examination::kMalformed) {
        ++(e.verdict == Examination::kBadChecksum ? counters_.bad_checksums
                                                  : counters_.bad_structure);
        ++counters_.bytes_skipped;
        ++pos;
      } else if (self.Accept(std::span<const std::uint8_t>(data + pos, e.length), t_host_ns)) {
        ++counters_.frames;
        counters_.bytes_in_frames += e.length;
        last_frame_ns_ = t_host_ns;
        pos += e.length;
      } else {
        ++counters_.bad_structure;
        ++counters_.bytes_skipped;
        ++pos;
      }
    }
    return pos;
  }

  // Examine may ask for more than one frame (Xbus looks at a message starting inside a candidate),
  // never for more than two: the buffer holds two maximal frames.
  std::size_t capacity_;
  std::unique_ptr<std::uint8_t[]> buffer_;
  std::size_t size_ = 0;
  std::int64_t timeout_ns_;
  std::int64_t pending_since_ns_ = 0;
  std::int64_t last_frame_ns_ = 0;
};

}  // namespace turncal::drivers
