#include "drivers/xbus/xbus_dialogue.h"

#include <fmt/format.h>

#include "drivers/bytes.h"
#include "drivers/xbus/xbus_decoder.h"
#include "drivers/xbus/xbus_encoder.h"

namespace turncal::drivers::xbus {

Dialogue::Dialogue(ByteLink* link, ExchangeOptions options) : link_(link), options_(options) {}

std::optional<std::vector<std::uint8_t>> Dialogue::Request(std::uint8_t mid,
                                                           std::span<const std::uint8_t> data,
                                                           const std::string& what,
                                                           std::string* error) {
  const std::vector<std::uint8_t> request = Message(mid, data);
  const auto ack = static_cast<std::uint8_t>(mid + 1);
  auto accept = [&](std::span<const std::uint8_t> f) { return f[2] == ack || f[2] == kError; };
  auto make = [](DecoderSink* sink) { return std::make_unique<XbusDecoder>("dialogue", sink); };
  const ExchangeResult r = Exchange(link_, request, make, accept, options_, what);
  if (!r.ok) {
    if (error) *error = r.error;
    return std::nullopt;
  }
  const auto payload = XbusDecoder::Payload(r.reply);
  if (r.reply[2] == kError) {
    const std::uint8_t code = payload.empty() ? 0 : payload[0];
    if (error)
      *error = fmt::format("{}: the device answered error 0x{:02X} ({})", what, code,
                           ErrorMeaning(code));
    return std::nullopt;
  }
  return std::vector<std::uint8_t>(payload.begin(), payload.end());
}

bool Dialogue::GoToConfig(std::string* error) {
  return Request(kGoToConfig, {}, "GoToConfig", error).has_value();
}

bool Dialogue::GoToMeasurement(std::string* error) {
  return Request(kGoToMeasurement, {}, "GoToMeasurement", error).has_value();
}

std::optional<DeviceIdentity> Dialogue::Identify(std::string* error) {
  DeviceIdentity id;
  const auto did = Request(kReqDid, {}, "ReqDID", error);
  if (!did) return std::nullopt;
  if (did->size() < 4) {
    if (error) *error = "ReqDID: the DeviceID reply is shorter than 4 bytes";
    return std::nullopt;
  }
  id.device_id = LoadU32(did->data());
  const auto code = Request(kReqProductCode, {}, "ReqProductCode", error);
  if (!code) return std::nullopt;
  id.product_code.assign(code->begin(), code->end());
  id.product_code.erase(id.product_code.find_last_not_of(std::string(" \0", 2)) + 1);
  const auto fw = Request(kReqFwRev, {}, "ReqFWRev", error);
  if (!fw) return std::nullopt;
  if (fw->size() >= 3) id.firmware = fmt::format("{}.{}.{}", (*fw)[0], (*fw)[1], (*fw)[2]);
  return id;
}

bool Dialogue::SetOutputConfiguration(const OutputConfiguration& wanted,
                                      OutputConfiguration* applied, std::string* error) {
  if (wanted.empty() || wanted.size() > 32) {
    if (error) *error = "SetOutputConfiguration: 1 to 32 outputs";
    return false;
  }
  std::vector<std::uint8_t> data;
  for (const auto& [xdi, rate] : wanted) {
    PutU16(&data, xdi);
    PutU16(&data, rate);
  }
  const auto ack = Request(kSetOutputConfiguration, data, "SetOutputConfiguration", error);
  if (!ack) return false;
  OutputConfiguration got;
  for (std::size_t at = 0; at + 4 <= ack->size(); at += 4) {
    got.emplace_back(LoadU16(ack->data() + at), LoadU16(ack->data() + at + 2));
  }
  if (applied) *applied = got;
  if (got != wanted) {
    std::string what;
    for (const auto& [xdi, rate] : got) what += fmt::format(" 0x{:04X}@{}", xdi, rate);
    if (error) *error = "SetOutputConfiguration: the device applied" + what + " instead";
    return false;
  }
  return true;
}

std::optional<XbusLegacyLayout> Dialogue::ReadLegacyLayout(std::string* error) {
  const auto mode = Request(kReqOutputMode, {}, "ReqOutputMode", error);
  if (!mode) return std::nullopt;
  const auto settings = Request(kReqOutputSettings, {}, "ReqOutputSettings", error);
  if (!settings) return std::nullopt;
  if (mode->size() < 2 || settings->size() < 4) {
    if (error) *error = "ReqOutputMode/ReqOutputSettings: short reply";
    return std::nullopt;
  }
  XbusLegacyLayout layout;
  layout.output_mode = LoadU16(mode->data());
  layout.output_settings = LoadU32(settings->data());
  if (!layout.PayloadSize(error)) return std::nullopt;
  return layout;
}

std::optional<DeviceIdentity> Dialogue::Configure(const OutputConfiguration& wanted,
                                                  std::string* error) {
  if (!GoToConfig(error)) return std::nullopt;
  auto id = Identify(error);
  if (!id) return std::nullopt;
  if (!SetOutputConfiguration(wanted, nullptr, error)) return std::nullopt;
  if (!GoToMeasurement(error)) return std::nullopt;
  return id;
}

}  // namespace turncal::drivers::xbus
