#include "protocol/sample_line.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <nlohmann/json.hpp>

namespace turncal::protocol {

namespace {

// Sample lines are written for every sample and subscriber shape (8 devices at 1000 Hz), so they
// are built with std::to_chars rather than a format string.
void AppendNumber(std::string* out, double v, std::chars_format format, int precision) {
  if (!std::isfinite(v)) {
    *out += "null";  // JSON has no inf or nan
    return;
  }
  char buffer[40];
  const auto r = std::to_chars(buffer, buffer + sizeof(buffer), v, format, precision);
  out->append(buffer, r.ptr);
}

// Seconds with 9 decimals (nanoseconds), from the integer nanoseconds.
void AppendFixed9(std::string* out, double seconds) {
  if (!std::isfinite(seconds) || std::abs(seconds) >= 9e9) {
    AppendNumber(out, seconds, std::chars_format::fixed, 9);
    return;
  }
  const auto ns = static_cast<std::int64_t>(std::llround(seconds * 1e9));
  const std::uint64_t magnitude = static_cast<std::uint64_t>(ns < 0 ? -ns : ns);
  if (ns < 0) *out += '-';
  char buffer[24];
  auto r = std::to_chars(buffer, buffer + sizeof(buffer), magnitude / 1'000'000'000u);
  out->append(buffer, r.ptr);
  *out += '.';
  r = std::to_chars(buffer, buffer + sizeof(buffer), magnitude % 1'000'000'000u);
  out->append(static_cast<std::size_t>(9 - (r.ptr - buffer)), '0');
  out->append(buffer, r.ptr);
}

void AppendInteger(std::string* out, std::int64_t v) {
  char buffer[24];
  const auto r = std::to_chars(buffer, buffer + sizeof(buffer), v);
  out->append(buffer, r.ptr);
}

void AppendString(std::string* out, const std::string& text) {
  const bool plain = std::all_of(text.begin(), text.end(), [](char c) {
    return c != '"' && c != '\\' && static_cast<unsigned char>(c) >= 0x20;
  });
  if (plain) {
    *out += '"';
    *out += text;
    *out += '"';
  } else {
    *out += nlohmann::json(text).dump();
  }
}

// A measured value: the shortest text that reads back to the same 32-bit float (at most 9
// significant digits, relative resolution 6e-8: finer than the 24-bit converters and the float32
// values the devices send).
void AppendMeasured(std::string* out, double v) {
  if (!std::isfinite(v)) {
    *out += "null";
    return;
  }
  char buffer[24];
  const auto r = std::to_chars(buffer, buffer + sizeof(buffer), static_cast<float>(v));
  out->append(buffer, r.ptr);
}

void AppendTriad(std::string* out, const char* key, const Eigen::Vector3d& v) {
  *out += ",\"";
  *out += key;
  *out += "\":[";
  for (int i = 0; i < 3; ++i) {
    if (i) *out += ',';
    AppendMeasured(out, v[i]);
  }
  *out += ']';
}

void AppendSampleTime(std::string* out, const Sample& s) {
  *out += ",\"device\":";
  AppendString(out, s.device);
  *out += ",\"t_host_ns\":";
  AppendInteger(out, s.t_host_ns);
  if (s.t_device_s) {
    *out += ",\"t_device\":";
    AppendFixed9(out, *s.t_device_s);
  }
  if (s.counter) {
    *out += ",\"counter\":";
    AppendInteger(out, *s.counter);
  }
}

void AppendRaw(std::string* out, const Sample& s) {
  if (s.acc_mps2) AppendTriad(out, "acc", *s.acc_mps2);
  if (s.gyr_radps) AppendTriad(out, "gyr", *s.gyr_radps);
  if (s.mag) AppendTriad(out, "mag", *s.mag);
  if (s.temp_c) {
    *out += ",\"temp\":";
    AppendNumber(out, *s.temp_c, std::chars_format::general, 4);
  }
  if (s.flags) {  // names, as turncal decode --json writes them
    *out += ",\"flags\":[";
    bool first = true;
    for (const auto& f : kSampleFlagNames) {
      if (!(s.flags & f.flag)) continue;
      if (!first) *out += ',';
      first = false;
      *out += '"';
      *out += f.name;
      *out += '"';
    }
    *out += ']';
  }
}

}  // namespace

void AppendSampleLine(std::string* out, const Sample& sample) {
  *out += "{\"class\":\"SAMPLE\"";
  AppendSampleTime(out, sample);
  AppendRaw(out, sample);
  *out += "}\n";
}

void AppendCorrectedLine(std::string* out, const Sample& sample, const CorrectedSample& c,
                         bool with_raw, bool with_sigma) {
  *out += "{\"class\":\"CORRECTED\"";
  AppendSampleTime(out, sample);
  if (c.t_sensor_s) {
    *out += ",\"t_sensor\":";
    AppendFixed9(out, *c.t_sensor_s);
  }
  if (c.acc_mps2) AppendTriad(out, "acc", *c.acc_mps2);
  if (c.acc_frame) {
    *out += ",\"acc_frame\":\"";
    *out += c.acc_frame;
    *out += '"';
  }
  if (c.mag) AppendTriad(out, "mag", *c.mag);
  if (c.mag_frame) {
    *out += ",\"mag_frame\":\"";
    *out += c.mag_frame;
    *out += '"';
  }
  if (with_sigma && c.acc_sigma) AppendTriad(out, "acc_sigma", *c.acc_sigma);
  if (with_sigma && c.mag_sigma) AppendTriad(out, "mag_sigma", *c.mag_sigma);
  // The gyro corrected by its model when one applies, else as the device sent it.
  if (c.gyr_radps) {
    AppendTriad(out, "gyr", *c.gyr_radps);
    *out += ",\"gyr_frame\":\"";
    *out += c.gyr_frame;
    *out += '"';
    if (with_sigma && c.gyr_sigma) AppendTriad(out, "gyr_sigma", *c.gyr_sigma);
  } else if (sample.gyr_radps) {
    AppendTriad(out, "gyr", *sample.gyr_radps);
  }
  *out += ",\"versions\":{";
  for (std::size_t k = 0; k < c.versions.size(); ++k) {
    if (k) *out += ',';
    AppendString(out, c.versions[k].first);
    *out += ':';
    AppendInteger(out, c.versions[k].second);
  }
  *out += "}";
  if (!c.temperature_flags.empty()) {
    *out += ",\"temp_flags\":{";
    for (std::size_t k = 0; k < c.temperature_flags.size(); ++k) {
      if (k) *out += ',';
      AppendString(out, c.temperature_flags[k].first);
      *out += ":\"";
      *out += c.temperature_flags[k].second;
      *out += '"';
    }
    *out += "}";
  }
  if (with_raw) {
    *out += ",\"raw\":{\"class\":\"SAMPLE\"";
    AppendRaw(out, sample);
    *out += "}";
  }
  *out += "}\n";
}

}  // namespace turncal::protocol
