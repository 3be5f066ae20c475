#include "drivers/mip/mip_encoder.h"

#include <cassert>
#include <cmath>

#include "drivers/bytes.h"
#include "drivers/checksum.h"
#include "drivers/mip/mip_decoder.h"

namespace turncal::drivers::mip {

std::vector<std::uint8_t> Packet(std::uint8_t set, std::span<const Field> fields) {
  std::vector<std::uint8_t> out = {0x75, 0x65, set, 0};
  for (const auto& f : fields) {
    assert(f.data.size() <= 253);
    out.push_back(static_cast<std::uint8_t>(f.data.size() + 2));
    out.push_back(f.descriptor);
    out.insert(out.end(), f.data.begin(), f.data.end());
  }
  assert(out.size() - 4 <= 255);
  out[3] = static_cast<std::uint8_t>(out.size() - 4);
  const std::uint16_t ck = MipChecksum(out);
  PutU16(&out, ck);
  return out;
}

namespace {

std::vector<std::uint8_t> Command(std::uint8_t set, std::uint8_t descriptor,
                                  std::vector<std::uint8_t> data = {}) {
  const Field f{descriptor, std::move(data)};
  return Packet(set, std::span<const Field>(&f, 1));
}

std::vector<std::uint8_t> Floats(const Eigen::Vector3d& v) {
  std::vector<std::uint8_t> out;
  for (int i = 0; i < 3; ++i) PutF32(&out, static_cast<float>(v[i]));
  return out;
}

}  // namespace

std::vector<std::uint8_t> Ping() { return Command(0x01, 0x01); }
std::vector<std::uint8_t> SetToIdle() { return Command(0x01, 0x02); }
std::vector<std::uint8_t> Resume() { return Command(0x01, 0x06); }
std::vector<std::uint8_t> GetDeviceInfo() { return Command(0x01, 0x03); }
std::vector<std::uint8_t> GetImuBaseRate() { return Command(0x0C, 0x06); }

std::vector<std::uint8_t> ImuMessageFormat(
    std::span<const std::pair<std::uint8_t, std::uint16_t>> descriptors) {
  std::vector<std::uint8_t> data = {0x01, static_cast<std::uint8_t>(descriptors.size())};
  for (const auto& [desc, decimation] : descriptors) {
    data.push_back(desc);
    PutU16(&data, decimation);
  }
  return Command(0x0C, 0x08, std::move(data));
}

std::vector<std::uint8_t> EnableStream(std::uint8_t data_set, bool on) {
  return Command(0x0C, 0x11, {0x01, data_set, static_cast<std::uint8_t>(on ? 1 : 0)});
}

std::vector<std::uint8_t> ReadStored(std::uint8_t descriptor) {
  return Command(0x0C, descriptor, {0x02});
}

std::vector<std::uint8_t> WriteStored(std::uint8_t descriptor, std::span<const double> values) {
  std::vector<std::uint8_t> data = {0x01};
  for (double v : values) PutF32(&data, static_cast<float>(v));
  return Command(0x0C, descriptor, data);
}

std::vector<std::uint8_t> StoredFunction(std::uint8_t descriptor, std::uint8_t function) {
  return Command(0x0C, descriptor, {function});
}

std::vector<std::uint8_t> Reply(std::uint8_t set, std::uint8_t echo, std::uint8_t code,
                                std::span<const Field> data) {
  std::vector<Field> fields = {{0xF1, {echo, code}}};
  fields.insert(fields.end(), data.begin(), data.end());
  return Packet(set, fields);
}

std::vector<std::uint8_t> SensorPacket(const Sample& s) {
  std::vector<Field> fields;
  if (s.t_device_s) {
    Field f{0xD5, {}};
    PutU64(&f.data, static_cast<std::uint64_t>(std::llround(*s.t_device_s * 1e9)));
    fields.push_back(std::move(f));
  }
  if (s.acc_mps2) fields.push_back({0x04, Floats(*s.acc_mps2 / kStandardGravity_mps2)});
  if (s.gyr_radps) fields.push_back({0x05, Floats(*s.gyr_radps)});
  if (s.mag) fields.push_back({0x06, Floats(*s.mag)});
  if (s.temp_c) {
    Field f{0x14, {}};
    for (int i = 0; i < 3; ++i) PutF32(&f.data, static_cast<float>(*s.temp_c));
    fields.push_back(std::move(f));
  }
  std::uint16_t over = 0;
  if (s.flags & kAccSaturated) over |= 0x0007;
  if (s.flags & kGyrSaturated) over |= 0x0070;
  if (s.flags & kMagSaturated) over |= 0x0700;
  if (over) {
    Field f{0x18, {}};
    PutU16(&f.data, over);
    fields.push_back(std::move(f));
  }
  return Packet(0x80, fields);
}

}  // namespace turncal::drivers::mip
