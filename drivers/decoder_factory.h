#pragma once
// A decoder by protocol name, with what each protocol needs from configuration.

#include <istream>
#include <memory>
#include <optional>

#include "drivers/gx2/gx2_decoder.h"
#include "drivers/xbus/xbus_decoder.h"

namespace turncal::drivers {

struct DecoderOptions {
  std::string device = "imu";
  Gx2Options gx2;
  XbusLegacyLayout xbus_legacy;  // used for Protocol::kXbusLegacy
};

// nullptr with a message when the options cannot work (e.g. a legacy layout this decoder cannot
// read).
// Pushes everything `in` holds into `decoder` in chunks of `chunk` bytes (host time 0: a raw file
// has no times), then Finish().
void DecodeStream(std::istream& in, Decoder* decoder, std::size_t chunk = 1 << 16);

std::unique_ptr<Decoder> MakeDecoder(Protocol protocol, const DecoderOptions& options,
                                     DecoderSink* sink, std::string* error);

}  // namespace turncal::drivers
