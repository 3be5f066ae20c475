#include "drivers/exchange.h"

#include <fmt/format.h>

namespace turncal::drivers {

namespace {

class ReplySink : public DecoderSink {
 public:
  explicit ReplySink(const std::function<bool(std::span<const std::uint8_t>)>& accept)
      : accept_(accept) {}
  void OnFrame(const FrameView& f) override {
    if (found) return;
    if (accept_(f.bytes)) {
      reply.assign(f.bytes.begin(), f.bytes.end());
      found = true;
    } else {
      ++skipped;
    }
  }
  void OnSample(const Sample&) override {}
  bool found = false;
  int skipped = 0;
  std::vector<std::uint8_t> reply;

 private:
  const std::function<bool(std::span<const std::uint8_t>)>& accept_;
};

}  // namespace

ExchangeResult Exchange(ByteLink* link, std::span<const std::uint8_t> request,
                        const std::function<std::unique_ptr<Decoder>(DecoderSink*)>& make_decoder,
                        const std::function<bool(std::span<const std::uint8_t>)>& accept,
                        const ExchangeOptions& options, const std::string& what) {
  ExchangeResult result;
  ReplySink sink(accept);
  auto decoder = make_decoder(&sink);
  std::uint8_t buffer[1024];
  for (int attempt = 1; attempt <= options.attempts; ++attempt) {
    result.attempts = attempt;
    if (!link->Write(request, &result.error)) {
      result.error = fmt::format("{}: cannot send the request: {}", what, result.error);
      return result;
    }
    const std::int64_t deadline =
        link->NowNs() +
        std::chrono::duration_cast<std::chrono::nanoseconds>(options.reply_timeout).count();
    while (!sink.found) {
      const std::int64_t left_ns = deadline - link->NowNs();
      if (left_ns <= 0) break;
      const long n =
          link->Read(buffer, std::chrono::milliseconds(left_ns / 1'000'000 + 1), &result.error);
      if (n < 0) {
        result.error = fmt::format("{}: read failed: {}", what, result.error);
        return result;
      }
      if (n > 0) decoder->Push({buffer, static_cast<std::size_t>(n)}, link->NowNs());
    }
    if (sink.found) break;
  }
  result.skipped_frames = sink.skipped;
  if (!sink.found) {
    result.error = fmt::format("{}: no reply after {} attempt(s) of {} ms", what, options.attempts,
                               options.reply_timeout.count());
    return result;
  }
  result.reply = std::move(sink.reply);
  result.ok = true;
  return result;
}

}  // namespace turncal::drivers
