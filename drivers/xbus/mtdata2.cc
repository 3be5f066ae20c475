#include "drivers/xbus/mtdata2.h"

#include <cmath>
#include <cstdlib>
#include <initializer_list>

#include "drivers/bytes.h"

namespace turncal::drivers::xbus {

VectorFrame FrameOf(std::uint16_t xdi) {
  switch (xdi & 0xC) {
    case 0x0:
      return VectorFrame::kEnu;
    case 0x4:
      return VectorFrame::kNed;
    case 0x8:
      return VectorFrame::kNwu;
    default:
      return VectorFrame::kUnknown;
  }
}

const char* ItemName(std::uint16_t type) {
  switch (type) {
    case kTemperature:
      return "Temperature";
    case kUtcTime:
      return "UTCTime";
    case kPacketCounter:
      return "PacketCounter";
    case kSampleTimeFine:
      return "SampleTimeFine";
    case kSampleTimeCoarse:
      return "SampleTimeCoarse";
    case kQuaternion:
      return "Quaternion";
    case kRotationMatrix:
      return "RotationMatrix";
    case kEulerAngles:
      return "EulerAngles";
    case kDeltaV:
      return "DeltaV";
    case kAcceleration:
      return "Acceleration";
    case kFreeAcceleration:
      return "FreeAcceleration";
    case kAltitudeEllipsoid:
      return "AltitudeEllipsoid";
    case kLatLon:
      return "LatLon";
    case kGnssPvtData:
      return "GNSSPVTData";
    case kRateOfTurn:
      return "RateOfTurn";
    case kDeltaQ:
      return "DeltaQ";
    case kMagneticField:
      return "MagneticField";
    case kVelocityXyz:
      return "VelocityXYZ";
    case kStatusByte:
      return "StatusByte";
    case kStatusWord:
      return "StatusWord";
    default:
      return nullptr;
  }
}

namespace {

bool Values(const Item& item, std::initializer_list<const char*> names,
            std::vector<NamedValue>* out) {
  const std::size_t size = static_cast<std::size_t>(ValueSize(item.format()));
  if (item.data.size() != size * names.size()) return false;
  const std::uint8_t* p = item.data.data();
  for (const char* name : names) {
    out->push_back({name, DecodeValue(p, item.format())});
    p += size;
  }
  return true;
}

// A packed big-endian record: sizes (1, 2 or 4 bytes; negative for signed) and names.
struct Field {
  const char* name;
  int size;
};

bool Record(const Item& item, std::initializer_list<Field> fields, std::vector<NamedValue>* out) {
  std::size_t total = 0;
  for (const auto& f : fields) total += static_cast<std::size_t>(std::abs(f.size));
  if (item.data.size() != total) return false;
  const std::uint8_t* p = item.data.data();
  for (const auto& f : fields) {
    double v = 0;
    switch (f.size) {
      case 1:
        v = p[0];
        break;
      case 2:
        v = LoadU16(p);
        break;
      case -2:
        v = static_cast<std::int16_t>(LoadU16(p));
        break;
      case 4:
        v = LoadU32(p);
        break;
      case -4:
        v = static_cast<std::int32_t>(LoadU32(p));
        break;
      default:
        return false;
    }
    out->push_back({f.name, v});
    p += std::abs(f.size);
  }
  return true;
}

}  // namespace

bool ItemValues(const Item& item, std::vector<NamedValue>* out) {
  switch (item.type()) {
    case kTemperature:
    case kAltitudeEllipsoid:
      return Values(item, {""}, out);
    case kAcceleration:
    case kRateOfTurn:
    case kMagneticField:
    case kDeltaV:
    case kFreeAcceleration:
    case kEulerAngles:
    case kVelocityXyz:
      return Values(item, {"X", "Y", "Z"}, out);
    case kQuaternion:
    case kDeltaQ:
      return Values(item, {"Q0", "Q1", "Q2", "Q3"}, out);
    case kRotationMatrix:
      return Values(item, {"a", "b", "c", "d", "e", "f", "g", "h", "i"}, out);
    case kLatLon:
      return Values(item, {"Lat", "Lon"}, out);
    case kPacketCounter:
      return Record(item, {{"", 2}}, out);
    case kSampleTimeFine:
    case kSampleTimeCoarse:
    case kStatusWord:
      return Record(item, {{"", 4}}, out);
    case kStatusByte:
      return Record(item, {{"", 1}}, out);
    case kUtcTime:
      return Record(item,
                    {{"Ns", 4},
                     {"Year", 2},
                     {"Month", 1},
                     {"Day", 1},
                     {"Hour", 1},
                     {"Minute", 1},
                     {"Second", 1},
                     {"Flags", 1}},
                    out);
    case kGnssPvtData:
      return Record(
          item, {{"ITOW", 4},    {"Year", 2},    {"Month", 1},    {"Day", 1},       {"Hour", 1},
                 {"Min", 1},     {"Sec", 1},     {"Valid", 1},    {"TAcc", 4},      {"Nano", -4},
                 {"FixType", 1}, {"Flags", 1},   {"NumSV", 1},    {"Reserved1", 1}, {"Lon", -4},
                 {"Lat", -4},    {"Height", -4}, {"HMSL", -4},    {"HAcc", 4},      {"VAcc", 4},
                 {"VelN", -4},   {"VelE", -4},   {"VelD", -4},    {"GSpeed", -4},   {"HeadMot", -4},
                 {"SAcc", 4},    {"HeadAcc", 4}, {"HeadVeh", -4}, {"GDOP", 2},      {"PDOP", 2},
                 {"TDOP", 2},    {"VDOP", 2},    {"HDOP", 2},     {"NDOP", 2},      {"EDOP", 2}},
          out);
    default:
      return false;
  }
}

bool ItemsFillPayload(std::span<const std::uint8_t> payload) {
  return ForEachItem(payload, [](const Item&) {});
}

}  // namespace turncal::drivers::xbus
