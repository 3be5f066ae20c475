#pragma once
// The Xbus configuration dialogue (PROTOCOLS.md "Configuration messages"): GoToConfig (skipping
// the data messages that keep streaming until the device obeys), device ID, product code,
// firmware revision, SetOutputConfiguration (the ack echoes what the device applied), and
// GoToMeasurement. An Error message (0x42) fails the step with its code's meaning.

#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "drivers/exchange.h"
#include "drivers/xbus/xbus_decoder.h"

namespace turncal::drivers::xbus {

using OutputConfiguration = std::vector<std::pair<std::uint16_t, std::uint16_t>>;  // XDI, Hz

struct DeviceIdentity {
  std::uint32_t device_id = 0;
  std::string product_code;
  std::string firmware;  // "major.minor.revision"
};

class Dialogue {
 public:
  explicit Dialogue(ByteLink* link, ExchangeOptions options = {});

  bool GoToConfig(std::string* error);
  bool GoToMeasurement(std::string* error);
  std::optional<DeviceIdentity> Identify(std::string* error);
  // Sends the configuration; `applied` receives what the device acknowledged. Fails when the
  // device applied something else (e.g. a lower rate), saying what.
  bool SetOutputConfiguration(const OutputConfiguration& wanted, OutputConfiguration* applied,
                              std::string* error);

  // Legacy MTi/MTx (MTData 0x32): the layout from ReqOutputMode (0xD0) and ReqOutputSettings
  // (0xD2), in config state. Fails when the decoder cannot read that layout.
  std::optional<XbusLegacyLayout> ReadLegacyLayout(std::string* error);

  // GoToConfig, Identify, SetOutputConfiguration, GoToMeasurement.
  std::optional<DeviceIdentity> Configure(const OutputConfiguration& wanted, std::string* error);

 private:
  std::optional<std::vector<std::uint8_t>> Request(std::uint8_t mid,
                                                   std::span<const std::uint8_t> data,
                                                   const std::string& what, std::string* error);
  ByteLink* link_;
  ExchangeOptions options_;
};

}  // namespace turncal::drivers::xbus
