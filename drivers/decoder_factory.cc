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

}  // namespace turncal::drivers
