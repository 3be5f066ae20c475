#include "drivers/mip/mip_stored_write.h"

#include <fmt/format.h>

namespace turncal::drivers::mip {

namespace {

// The first entry where the read-back is not, bit for bit, the float that was sent; -1 when all
// agree; -2 when the device returned no such quantity.
int FirstDifference(const StoredCalibration& read, std::uint8_t descriptor,
                    const std::vector<double>& sent) {
  const std::vector<double> got = StoredValues(read, descriptor);
  if (got.size() != sent.size()) return -2;
  for (std::size_t i = 0; i < got.size(); ++i) {
    if (static_cast<float>(got[i]) != static_cast<float>(sent[i])) return static_cast<int>(i);
  }
  return -1;
}

// Reads everything back and compares `values(step)` for every step; false with the reason.
template <typename Values>
bool ReadBackAndCompare(Dialogue* d, const std::vector<StoredWriteStep>& steps, std::size_t count,
                        Values values, StoredWriteOutcome* out, std::string* error) {
  auto read = d->ReadStoredCalibration(error);
  if (!read) return false;
  out->read_back = read;
  for (std::size_t i = 0; i < count; ++i) {
    const StoredWriteStep& s = steps[i];
    const int at = FirstDifference(*read, s.descriptor, values(s));
    if (at == -2) {
      *error = fmt::format("read back {}: the device returned no value",
                           StoredQuantityName(s.descriptor));
      return false;
    }
    if (at >= 0) {
      *error = fmt::format("read back {}: entry {} is {:.9g}, {:.9g} was written",
                           StoredQuantityName(s.descriptor), at,
                           StoredValues(*read, s.descriptor)[static_cast<std::size_t>(at)],
                           static_cast<float>(values(s)[static_cast<std::size_t>(at)]));
      return false;
    }
  }
  return true;
}

}  // namespace

const char* ToString(StoredWriteState state) {
  switch (state) {
    case StoredWriteState::kUnchanged:
      return "unchanged";
    case StoredWriteState::kWritten:
      return "written";
    case StoredWriteState::kSaved:
      return "saved";
    case StoredWriteState::kRolledBack:
      return "rolled_back";
    case StoredWriteState::kUnknown:
      return "unknown";
  }
  return "unknown";
}

std::vector<double> StoredValues(const StoredCalibration& stored, std::uint8_t descriptor) {
  const auto vector = [](const std::optional<Eigen::Vector3d>& v) {
    return v ? std::vector<double>{v->x(), v->y(), v->z()} : std::vector<double>{};
  };
  switch (descriptor) {
    case 0x37:
      return vector(stored.accel_bias);
    case 0x38:
      return vector(stored.gyro_bias);
    case 0x3A:
      return vector(stored.hard_iron);
    case 0x3B:
    case 0x33: {
      const std::optional<Eigen::Matrix3d>& m =
          descriptor == 0x3B ? stored.soft_iron : stored.transform;
      std::vector<double> out;
      if (m) {
        for (int i = 0; i < 9; ++i) out.push_back((*m)(i / 3, i % 3));
      }
      return out;
    }
    default:
      return {};
  }
}

StoredWriteOutcome WriteStoredCalibration(Dialogue* d, const std::vector<StoredWriteStep>& steps,
                                          bool save) {
  StoredWriteOutcome out;
  const auto say = [&](std::string line) { out.log.push_back(std::move(line)); };
  const auto resume = [&] {
    std::string e;
    if (d->Resume(&e)) {
      say("resume: ok");
    } else {
      say("resume: " + e);
      if (out.error.empty()) out.error = e;
    }
  };
  std::string e;
  if (!d->SetToIdle(&e)) {
    out.error = e;
    say("set to idle: " + e);
    resume();
    return out;  // nothing written
  }
  say("set to idle: ok");

  std::size_t attempted = 0;
  std::size_t saves_attempted = 0;
  bool failed = false;
  std::uint8_t code = 0;
  for (const StoredWriteStep& s : steps) {
    // A write whose reply was lost may have happened: it is rolled back too; a NACK's did not.
    if (!d->WriteStored(s.descriptor, s.values, &e, &code)) {
      if (code == 0xFF) ++attempted;
      failed = true;
      break;
    }
    ++attempted;
    say(fmt::format("write {}: ok", StoredQuantityName(s.descriptor)));
  }
  if (!failed) {
    failed = !ReadBackAndCompare(
        d, steps, steps.size(), [](const StoredWriteStep& s) { return s.values; }, &out, &e);
    if (!failed) say("read back: every value as written, bit for bit");
  }
  if (!failed && save) {
    for (const StoredWriteStep& s : steps) {
      if (!d->StoredFunction(s.descriptor, 3, &e, &code)) {
        if (code == 0xFF) ++saves_attempted;
        failed = true;
        break;
      }
      ++saves_attempted;
      say(fmt::format("save {}: ok", StoredQuantityName(s.descriptor)));
    }
  }
  if (!failed) {
    out.state = save ? StoredWriteState::kSaved : StoredWriteState::kWritten;
    resume();
    return out;
  }
  out.error = e;
  say("failed: " + e);

  // Rollback: the old values of every quantity attempted, saved again where a save was sent.
  std::string r;
  bool rolled = true;
  for (std::size_t i = 0; i < attempted && rolled; ++i) {
    rolled = d->WriteStored(steps[i].descriptor, steps[i].old_values, &r);
    say(fmt::format("rollback: write the old {}: {}", StoredQuantityName(steps[i].descriptor),
                    rolled ? "ok" : r));
  }
  for (std::size_t i = 0; i < saves_attempted && rolled; ++i) {
    rolled = d->StoredFunction(steps[i].descriptor, 3, &r);
    say(fmt::format("rollback: save the old {}: {}", StoredQuantityName(steps[i].descriptor),
                    rolled ? "ok" : r));
  }
  if (rolled) {
    rolled = ReadBackAndCompare(
        d, steps, attempted, [](const StoredWriteStep& s) { return s.old_values; }, &out, &r);
    say(rolled ? "rollback: read back: the old values, bit for bit" : "rollback: " + r);
  }
  if (rolled) {
    out.state = attempted == 0 ? StoredWriteState::kUnchanged : StoredWriteState::kRolledBack;
  } else {
    out.state = StoredWriteState::kUnknown;
    out.rollback_error = r;
  }
  resume();
  return out;
}

void SetStoredValues(StoredCalibration* stored, std::uint8_t descriptor,
                     const std::vector<double>& values) {
  if ((descriptor == 0x3B || descriptor == 0x33) && values.size() == 9) {
    Eigen::Matrix3d m;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) m(r, c) = values[static_cast<std::size_t>(3 * r + c)];
    }
    (descriptor == 0x3B ? stored->soft_iron : stored->transform) = m;
    return;
  }
  if (values.size() != 3) return;
  const Eigen::Vector3d x(values[0], values[1], values[2]);
  if (descriptor == 0x37) stored->accel_bias = x;
  if (descriptor == 0x38) stored->gyro_bias = x;
  if (descriptor == 0x3A) stored->hard_iron = x;
}

const char* StoredQuantityKey(std::uint8_t descriptor) {
  switch (descriptor) {
    case 0x37:
      return "accel_bias_g";
    case 0x38:
      return "gyro_bias_radps";
    case 0x3A:
      return "hard_iron_gauss";
    case 0x33:
      return "sensor_to_vehicle";
    default:
      return "soft_iron";
  }
}

const char* StoredQuantityUnit(std::uint8_t descriptor) {
  switch (descriptor) {
    case 0x37:
      return "g";
    case 0x38:
      return "rad/s";
    case 0x3A:
      return "Gauss";
    default:
      return "";
  }
}

}  // namespace turncal::drivers::mip
