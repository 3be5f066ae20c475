#pragma once
// A decoder by protocol name, with what each protocol needs from configuration.

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
std::unique_ptr<Decoder> MakeDecoder(Protocol protocol, const DecoderOptions& options,
                                     DecoderSink* sink, std::string* error);

}  // namespace turncal::drivers
