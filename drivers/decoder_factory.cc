#include "drivers/decoder_factory.h"

#include "drivers/mip/mip_decoder.h"

namespace turncal::drivers {

std::unique_ptr<Decoder> MakeDecoder(Protocol protocol, const DecoderOptions& options,
                                     DecoderSink* sink, std::string* error) {
  switch (protocol) {
    case Protocol::kMip:
      return std::make_unique<MipDecoder>(options.device, sink);
    case Protocol::kGx2:
      if (!(options.gx2.timer_ticks_per_s > 0)) {
        if (error) *error = "the GX2 timer rate must be > 0 ticks/s";
        return nullptr;
      }
      return std::make_unique<Gx2Decoder>(options.device, sink, options.gx2);
    case Protocol::kXbus:
      return std::make_unique<XbusDecoder>(options.device, sink);
    case Protocol::kXbusLegacy:
      if (!options.xbus_legacy.PayloadSize(error)) return nullptr;
      return std::make_unique<XbusDecoder>(options.device, sink, options.xbus_legacy);
  }
  if (error) *error = "unknown protocol";
  return nullptr;
}

void DecodeStream(std::istream& in, Decoder* decoder, std::size_t chunk) {
  std::vector<char> buffer(std::max<std::size_t>(chunk, 1));
  while (in) {
    in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
    const auto n = static_cast<std::size_t>(in.gcount());
    if (n == 0) break;
    decoder->Push(
        std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(buffer.data()), n), 0);
  }
  decoder->Finish();
}

}  // namespace turncal::drivers
