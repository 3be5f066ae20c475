#pragma once
// Helpers shared by the decoder tests: a sink that keeps everything, hex parsing, fixture paths.

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "drivers/decoder.h"

namespace turncal::drivers::testing {

struct Collected {
  std::vector<std::uint8_t> kind;
  std::vector<std::vector<std::uint8_t>> bytes;
  std::vector<bool> carries_sample;
};

class CollectingSink : public DecoderSink {
 public:
  void OnFrame(const FrameView& f) override {
    frames.kind.push_back(f.kind);
    frames.bytes.emplace_back(f.bytes.begin(), f.bytes.end());
    frames.carries_sample.push_back(f.carries_sample);
  }
  void OnSample(const Sample& s) override { samples.push_back(s); }
  Collected frames;
  std::vector<Sample> samples;
};

inline std::vector<std::uint8_t> Hex(const std::string& text) {
  std::vector<std::uint8_t> out;
  std::istringstream in(text);
  std::string byte;
  while (in >> byte) out.push_back(static_cast<std::uint8_t>(std::stoul(byte, nullptr, 16)));
  return out;
}

// ../shared/fixtures/<relative>, or empty when the shared folder is absent.
inline std::filesystem::path Fixture(const std::string& relative) {
  const char* shared = std::getenv("TURNCAL_SHARED_DIR");
  if (shared == nullptr) return {};
  const std::filesystem::path p = std::filesystem::path(shared) / "fixtures" / relative;
  return std::filesystem::exists(p) ? p : std::filesystem::path();
}

inline std::vector<std::uint8_t> ReadFile(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::vector<std::uint8_t>((std::istreambuf_iterator<char>(in)),
                                   std::istreambuf_iterator<char>());
}

inline std::string ReadText(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// Every byte is in a frame, skipped, or pending.
inline bool BytesAccountedFor(const Decoder& d) {
  const DecoderCounters& c = d.counters();
  return c.bytes_in == c.bytes_in_frames + c.bytes_skipped + d.pending_bytes();
}

}  // namespace turncal::drivers::testing
