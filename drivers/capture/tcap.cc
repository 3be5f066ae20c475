#include "drivers/capture/tcap.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>

namespace turncal::drivers {

namespace {

void PutLe(std::uint64_t v, int bytes, std::vector<std::uint8_t>* out) {
  for (int i = 0; i < bytes; ++i) out->push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}

std::uint64_t GetLe(const std::uint8_t* p, int bytes) {
  std::uint64_t v = 0;
  for (int i = bytes - 1; i >= 0; --i) v = v << 8 | p[i];
  return v;
}

}  // namespace

std::string EncodeCaptureHeader(const CaptureHeader& header) {
  nlohmann::json devices = nlohmann::json::array();
  for (const auto& d : header.devices) {
    nlohmann::json dev = {{"name", d.name}, {"protocol", ToString(d.protocol)}, {"baud", d.baud}};
    if (d.output_mode) dev["output_mode"] = *d.output_mode;
    if (d.output_settings) dev["output_settings"] = *d.output_settings;
    devices.push_back(dev);
  }
  const nlohmann::json j = {
      {"devices", devices}, {"created", header.created}, {"note", header.note}};
  return "TCAP1 " + j.dump() + "\n";
}

void AppendCaptureRecord(RecordType type, std::uint8_t device, std::uint64_t t_ns,
                         std::span<const std::uint8_t> payload, std::vector<std::uint8_t>* out) {
  out->push_back(static_cast<std::uint8_t>(type));
  out->push_back(device);
  PutLe(t_ns, 8, out);
  PutLe(payload.size(), 4, out);
  out->insert(out->end(), payload.begin(), payload.end());
}

std::unique_ptr<CaptureWriter> CaptureWriter::Create(const std::string& path,
                                                     const CaptureHeader& header,
                                                     std::string* error) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) {
    if (error) *error = "cannot create '" + path + "': " + std::strerror(errno);
    return nullptr;
  }
  std::unique_ptr<CaptureWriter> w(new CaptureWriter(f, path));
  const std::string line = EncodeCaptureHeader(header);
  if (std::fwrite(line.data(), 1, line.size(), f) != line.size() || !w->Flush(error)) {
    if (error && error->empty()) *error = "cannot write '" + path + "'";
    return nullptr;
  }
  return w;
}

CaptureWriter::~CaptureWriter() {
  if (file_) std::fclose(file_);
}

bool CaptureWriter::Append(RecordType type, std::uint8_t device, std::uint64_t t_ns,
                           std::span<const std::uint8_t> payload, std::string* error) {
  if (file_ == nullptr) {
    if (error) *error = "the capture is closed";
    return false;
  }
  if (!failed_.empty()) {
    if (error) *error = failed_;
    return false;
  }
  if (payload.size() > kCaptureMaxPayload) {
    if (error) *error = "a record payload is limited to 16 MiB";
    return false;
  }
  scratch_.clear();
  AppendCaptureRecord(type, device, t_ns, payload, &scratch_);
  if (std::fwrite(scratch_.data(), 1, scratch_.size(), file_) != scratch_.size()) {
    failed_ = "cannot write '" + path_ + "': " + std::strerror(errno);
    if (error) *error = failed_;
    return false;
  }
  ++records_;
  return true;
}

bool CaptureWriter::Flush(std::string* error) {
  if (file_ && std::fflush(file_) != 0) {
    failed_ = "cannot write '" + path_ + "': " + std::strerror(errno);
    if (error) *error = failed_;
    return false;
  }
  return true;
}

bool CaptureWriter::Close(std::string* error) {
  if (file_ == nullptr) return true;
  bool ok = Flush(error);
  if (ok && ::fsync(::fileno(file_)) != 0) {
    if (error) *error = "cannot sync '" + path_ + "': " + std::strerror(errno);
    ok = false;
  }
  if (std::fclose(file_) != 0 && ok) {
    if (error) *error = "cannot close '" + path_ + "': " + std::strerror(errno);
    ok = false;
  }
  file_ = nullptr;
  return ok;
}

std::optional<bool> FileLooksLikeCapture(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return std::nullopt;
  std::uint8_t magic[6] = {};
  in.read(reinterpret_cast<char*>(magic), sizeof magic);
  return in.gcount() == static_cast<std::streamsize>(sizeof magic) && LooksLikeCapture(magic);
}

bool LooksLikeCapture(std::span<const std::uint8_t> b) {
  return b.size() >= 6 && std::memcmp(b.data(), "TCAP1 ", 6) == 0;
}

bool CaptureReader::Open(const std::string& path, std::string* error) {
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> file(std::fopen(path.c_str(), "rb"),
                                                       &std::fclose);
  if (!file) {
    if (error) *error = "cannot open '" + path + "'";
    return false;
  }
  std::uint64_t size = 0;
  if (std::fseek(file.get(), 0, SEEK_END) == 0) {
    const long end = std::ftell(file.get());
    if (end > 0) size = static_cast<std::uint64_t>(end);
    std::rewind(file.get());
  }
  // The header line, at most kCaptureMaxHeaderLine, and the records' first bytes.
  std::vector<std::uint8_t> bytes(kCaptureMaxHeaderLine + 1);
  bytes.resize(std::fread(bytes.data(), 1, bytes.size(), file.get()));
  if (!Parse(std::move(bytes), error)) return false;
  file_ = std::move(file);
  size_ = size;
  return true;
}

bool CaptureReader::Refill(std::size_t need) {
  if (bytes_.size() - at_ >= need) return true;
  if (!file_) return false;
  bytes_.erase(bytes_.begin(), bytes_.begin() + static_cast<long>(at_));
  consumed_ += at_;
  at_ = 0;
  constexpr std::size_t kChunk = 1u << 20;
  while (bytes_.size() < need && file_) {
    const std::size_t had = bytes_.size();
    bytes_.resize(had + std::max(kChunk, need - had));
    const std::size_t got = std::fread(bytes_.data() + had, 1, bytes_.size() - had, file_.get());
    bytes_.resize(had + got);
    if (got == 0) file_.reset();
  }
  return bytes_.size() >= need;
}

bool CaptureReader::Parse(std::vector<std::uint8_t> bytes, std::string* error) {
  bytes_ = std::move(bytes);
  at_ = 0;
  file_.reset();
  consumed_ = 0;
  size_ = bytes_.size();
  truncated_ = false;
  error_.clear();
  header_ = {};
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!LooksLikeCapture(bytes_))
    return fail("not a capture: the file does not start with 'TCAP1 '");
  const auto limit = std::min(bytes_.size(), kCaptureMaxHeaderLine);
  const auto nl = std::find(bytes_.begin(), bytes_.begin() + static_cast<long>(limit), '\n');
  if (nl == bytes_.begin() + static_cast<long>(limit))
    return fail("capture header line has no end");
  const std::string line(bytes_.begin() + 6, nl);
  const auto j = nlohmann::json::parse(line, nullptr, false);
  if (j.is_discarded() || !j.is_object()) return fail("capture header is not a JSON object");
  if (j.contains("devices") && j["devices"].is_array()) {
    for (const auto& d : j["devices"]) {
      CaptureDevice dev;
      if (d.contains("name") && d["name"].is_string()) dev.name = d["name"];
      if (d.contains("protocol") && d["protocol"].is_string()) {
        const auto p = ParseProtocol(d["protocol"].get<std::string>());
        if (!p) return fail("capture header names an unknown protocol");
        dev.protocol = *p;
      }
      if (d.contains("baud") && d["baud"].is_number_integer()) dev.baud = d["baud"];
      if (d.contains("output_mode") && d["output_mode"].is_number_unsigned() &&
          d["output_mode"].get<std::uint64_t>() <= 0xFFFF) {
        dev.output_mode = static_cast<std::uint16_t>(d["output_mode"].get<std::uint64_t>());
      }
      if (d.contains("output_settings") && d["output_settings"].is_number_unsigned() &&
          d["output_settings"].get<std::uint64_t>() <= 0xFFFFFFFF) {
        dev.output_settings = static_cast<std::uint32_t>(d["output_settings"].get<std::uint64_t>());
      }
      header_.devices.push_back(dev);
    }
  }
  if (j.contains("created") && j["created"].is_string()) header_.created = j["created"];
  if (j.contains("note") && j["note"].is_string()) header_.note = j["note"];
  at_ = static_cast<std::size_t>(nl - bytes_.begin()) + 1;
  return true;
}

bool CaptureReader::Next(CaptureRecord* r) {
  if (!error_.empty() || (at_ >= bytes_.size() && !Refill(1))) return false;
  if (!Refill(kCaptureRecordHeader)) {
    truncated_ = true;
    return false;
  }
  const std::uint8_t* p = bytes_.data() + at_;
  const auto type = p[0];
  const auto length = static_cast<std::uint32_t>(GetLe(p + 10, 4));
  if ((type != 'D' && type != 'T' && type != 'E') || length > kCaptureMaxPayload) {
    error_ = "corrupt record at byte " + std::to_string(consumed_ + at_);
    return false;
  }
  if (!Refill(kCaptureRecordHeader + length)) {
    truncated_ = true;
    return false;
  }
  p = bytes_.data() + at_;
  r->type = static_cast<RecordType>(type);
  r->device = p[1];
  r->t_ns = GetLe(p + 2, 8);
  r->payload.assign(p + kCaptureRecordHeader, p + kCaptureRecordHeader + length);
  at_ += kCaptureRecordHeader + length;
  return true;
}

}  // namespace turncal::drivers
