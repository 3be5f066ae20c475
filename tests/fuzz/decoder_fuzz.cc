// libFuzzer target for one decoder (chosen at compile time by TURNCAL_FUZZ_PROTOCOL, a
// drivers::Protocol value). The input is split into pushes whose sizes come from the input
// itself; time advances so the timeout path runs too. Invariants checked on every input: every
// byte is in a frame, skipped or pending; nothing is pending after Finish; every frame is at
// most the protocol's maximum length.
//
// Build (clang): cmake -S . -B build-fuzz -DCMAKE_CXX_COMPILER=clang++ -DTURNCAL_FUZZ=ON
// Run: build-fuzz/tests/fuzz/mip_fuzz -max_total_time=600 -max_len=40000 tests/fuzz/corpus/mip
#include <cstddef>
#include <cstdint>

#include "drivers/decoder_factory.h"
#include "drivers/mip/mip_decoder.h"

namespace {

class CheckingSink : public turncal::drivers::DecoderSink {
 public:
  void OnFrame(const turncal::drivers::FrameView& f) override {
    if (f.bytes.empty() || f.bytes.size() > turncal::drivers::kXbusMaxFrame) __builtin_trap();
  }
  void OnSample(const turncal::Sample& s) override {
    if (s.acc_mps2) sum_ += s.acc_mps2->x();
  }
  double sum_ = 0;
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace turncal::drivers;
  CheckingSink sink;
  DecoderOptions options;
  options.xbus_legacy.output_mode = 0x0807;
  options.xbus_legacy.output_settings = 0x00000101;
  auto decoder = MakeDecoder(static_cast<Protocol>(TURNCAL_FUZZ_PROTOCOL), options, &sink, nullptr);
  if (!decoder) __builtin_trap();
  std::int64_t t = 0;
  std::size_t at = 0;
  while (at < size) {
    // Pushes from 1 byte to 16 KiB: small ones exercise the buffered path, large ones the
    // in-place scan and the look-ahead past one frame.
    const std::size_t n = std::min<std::size_t>(
        size - at, data[at] < 200 ? 1 + data[at] % 97 : 1 + (data[at] - 200) * 300);
    decoder->Push({data + at, n}, t);
    at += n;
    t += 5'000'000;  // 5 ms a push
    if (data[at - 1] % 7 == 0) decoder->CheckTimeout(t + 500'000'000);
    const auto& c = decoder->counters();
    if (c.bytes_in != c.bytes_in_frames + c.bytes_skipped + decoder->pending_bytes()) {
      __builtin_trap();
    }
  }
  decoder->Finish();
  const auto& c = decoder->counters();
  if (decoder->pending_bytes() != 0 || c.bytes_in != size ||
      c.bytes_in != c.bytes_in_frames + c.bytes_skipped) {
    __builtin_trap();
  }
  return 0;
}
