#pragma once
// The capture file format `.tcap` (DESIGN.md "Capture file"; docs/capture-format.md): one text
// line `TCAP1 <json header>\n`, then records `type u8 | device u8 | t_ns u64 LE | length u32 LE |
// payload`. Type 'D' bytes received from a device, 'T' bytes sent to it, 'E' an event (JSON, e.g.
// a pose command); t_ns is host monotonic time since the capture began. Appending never rewrites
// earlier bytes, so a capture cut short is readable up to its last whole record.

#include <cstdint>
#include <cstdio>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "drivers/device_spec.h"

namespace turncal::drivers {

inline constexpr std::size_t kCaptureRecordHeader = 14;        // type, device, t_ns, length
inline constexpr std::uint32_t kCaptureMaxPayload = 1u << 24;  // 16 MiB: larger is corruption
inline constexpr std::size_t kCaptureMaxHeaderLine = 1u << 20;

struct CaptureDevice {
  std::string name;
  Protocol protocol = Protocol::kMip;
  int baud = 115200;
  // xbus-legacy: the MTData layout the device was in (header keys "output_mode",
  // "output_settings"), so the capture decodes without configuration.
  std::optional<std::uint16_t> output_mode;
  std::optional<std::uint32_t> output_settings;
};

struct CaptureHeader {
  std::vector<CaptureDevice> devices;
  std::string created;  // ISO 8601 UTC, or "simulated" for simulator output
  std::string note;
};

enum class RecordType : std::uint8_t { kReceived = 'D', kSent = 'T', kEvent = 'E' };

struct CaptureRecord {
  RecordType type = RecordType::kReceived;
  std::uint8_t device = 0;  // index into CaptureHeader::devices
  std::uint64_t t_ns = 0;
  std::vector<std::uint8_t> payload;
};

// The header line (with its '\n') and one record, as bytes.
std::string EncodeCaptureHeader(const CaptureHeader& header);
void AppendCaptureRecord(RecordType type, std::uint8_t device, std::uint64_t t_ns,
                         std::span<const std::uint8_t> payload, std::vector<std::uint8_t>* out);

// Writes a capture: the header at creation, then appended records. Buffered; Flush() hands
// everything to the kernel, Close() also fsyncs. After the first failed write every later Append
// fails with that error (the file stays readable up to its last whole record).
class CaptureWriter {
 public:
  // nullptr with a message when the file cannot be created.
  static std::unique_ptr<CaptureWriter> Create(const std::string& path, const CaptureHeader& header,
                                               std::string* error);
  ~CaptureWriter();
  CaptureWriter(const CaptureWriter&) = delete;
  CaptureWriter& operator=(const CaptureWriter&) = delete;

  bool Append(RecordType type, std::uint8_t device, std::uint64_t t_ns,
              std::span<const std::uint8_t> payload, std::string* error);
  bool Flush(std::string* error);
  bool Close(std::string* error);
  std::uint64_t records() const { return records_; }

 private:
  CaptureWriter(std::FILE* file, std::string path) : file_(file), path_(std::move(path)) {}
  std::FILE* file_;
  std::string path_;
  std::vector<std::uint8_t> scratch_;
  std::uint64_t records_ = 0;
  // After a failed write the file may end inside a record: nothing more is appended, so a reader
  // still finds every whole record before it.
  std::string failed_;
};

// Reads a capture from memory or a file. A truncated last record ends the records cleanly
// (truncated() is then true); a record whose type or length cannot be valid stops with an error.
// A file is read as the records are asked for, a MiB at a time: hours of recording take no more
// memory than a minute (turncal noise reads 10-hour captures).
class CaptureReader {
 public:
  // From the bytes of a whole file; false with a message when the header line is not a TCAP1
  // header.
  bool Parse(std::vector<std::uint8_t> bytes, std::string* error);
  bool Open(const std::string& path, std::string* error);
  // Bytes of the file (or of the parsed bytes) read past so far, and the file's size (0 when
  // unknown): for progress.
  std::uint64_t position() const { return consumed_ + at_; }
  std::uint64_t size() const { return size_; }

  const CaptureHeader& header() const { return header_; }
  // The next whole record; false at the end (see truncated() and error()).
  bool Next(CaptureRecord* record);
  bool truncated() const { return truncated_; }
  const std::string& error() const { return error_; }
  std::size_t trailing_bytes() const { return truncated_ ? bytes_.size() - at_ : 0; }

 private:
  // Keeps at least `need` bytes after at_ when the file has them; false when it has not.
  bool Refill(std::size_t need);

  std::vector<std::uint8_t> bytes_;
  std::size_t at_ = 0;
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> file_{nullptr, &std::fclose};
  std::uint64_t consumed_ = 0;  // file bytes before bytes_[0]
  std::uint64_t size_ = 0;
  CaptureHeader header_;
  bool truncated_ = false;
  std::string error_;
};

// True when the file starts with "TCAP1 " (otherwise it is taken as a raw .bin stream).
bool LooksLikeCapture(std::span<const std::uint8_t> first_bytes);
// Whether the file at `path` starts like a capture; nullopt when it cannot be opened.
std::optional<bool> FileLooksLikeCapture(const std::string& path);

}  // namespace turncal::drivers
