#pragma once
// Tests' helpers: a `turncal sim` capture built in-process (sim/capture.h), encoded to .tcap bytes
// and replayed through the decoders into the sequencer (daemon/station/capture_replay.h), or
// written to a .tcap file in the test's temporary folder.

#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdint>
#include <string>
#include <vector>

#include "daemon/station/capture_replay.h"
#include "sim/capture.h"

namespace turncal {

inline daemon::ReplayResult ReplaySimCapture(const sim::SimCapture& c,
                                             const daemon::ReplayOptions& options) {
  std::vector<std::uint8_t> bytes = sim::EncodeSimCapture(c);
  drivers::CaptureReader reader;
  std::string error;
  EXPECT_TRUE(reader.Parse(std::move(bytes), &error)) << error;
  daemon::ReplayResult result;
  EXPECT_TRUE(daemon::ReplayCapture(&reader, options, &result, &error)) << error;
  return result;
}

// Writes the capture to TempDir()/STEM_PID.tcap and returns the path.
inline std::string WriteSimCaptureFile(const sim::SimCapture& c, const std::string& stem) {
  const std::string path = ::testing::TempDir() + stem + "_" + std::to_string(::getpid()) + ".tcap";
  std::string error;
  auto writer = drivers::CaptureWriter::Create(path, c.header, &error);
  EXPECT_TRUE(writer) << error;
  for (const auto& r : c.records)
    EXPECT_TRUE(writer->Append(r.type, r.device, r.t_ns, r.payload, &error));
  EXPECT_TRUE(writer->Close(&error)) << error;
  return path;
}

}  // namespace turncal
