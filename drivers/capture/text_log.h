#pragma once
// Foreign recordings (issue 22, "Foreign data in"): text logs with a time column and triad
// columns, as other tools export them, and imu_tk's `.mat` text files (time, x, y, z raw counts,
// one file per sensor) as one such layout.
//
// A line is a sample when every column the layout names parses as a finite number; fields are
// separated by commas, semicolons, tabs or blanks. Other lines (a header, comments, a truncated
// last line) are skipped and counted, the first one's number and reason kept. A sample whose time
// does not increase is dropped and counted (the sequencer needs time to go forward). Values become
// the sample's units as (value - offset) x scale per triad: m/s^2, rad/s and the magnetometer's
// own unit; time as value x time_scale seconds, the host clock from the first sample's time.

#include <array>
#include <cstdint>
#include <istream>
#include <string>
#include <vector>

#include "core/sequencing/sample.h"

namespace turncal::drivers {

struct TriadColumns {
  std::array<int, 3> column{-1, -1, -1};  // 0-based; -1: the log has no such triad
  double offset = 0.0;                    // subtracted first (raw counts: the mid-scale)
  double scale = 1.0;                     // then multiplied: to m/s^2, rad/s or the mag's unit
  bool present() const { return column[0] >= 0; }
};

struct TextLogLayout {
  int time_column = 0;
  double time_scale = 1.0;  // to seconds (1e-3 for milliseconds)
  TriadColumns acc, gyr, mag;

  // False with a message: no time column, no triad, a triad with one or two columns, a column
  // named twice, or a scale that is not finite and nonzero.
  bool IsValid(std::string* error) const;
};

// A layout from a column list such as "t,ax,ay,az,gx,gy,gz": one name per column in order, t the
// time, ax ay az / gx gy gz / mx my mz the triads' axes, "-" a column to ignore. Scales and
// offsets are left as they are.
bool ParseColumnSpec(const std::string& spec, TextLogLayout* layout, std::string* error);

struct TextLogStats {
  std::int64_t lines = 0;      // read, the skipped ones included
  std::int64_t samples = 0;    // taken
  std::int64_t skipped = 0;    // not numbers where the layout needs them, or too few fields
  std::int64_t backwards = 0;  // dropped: their time did not increase
  std::string first_skipped;   // "line N: why"
  double t_first_s = 0.0, t_last_s = 0.0;

  // Samples per second over the log (0 with fewer than two samples).
  double rate_hz() const;
};

// Reads `in` to its end, appending to `out` (each sample's device set to `device`). False with
// *error only when the layout is invalid or no line is a sample.
bool ReadTextLog(std::istream& in, const TextLogLayout& layout, const std::string& device,
                 std::vector<Sample>* out, TextLogStats* stats, std::string* error);
bool ReadTextLogFile(const std::string& path, const TextLogLayout& layout,
                     const std::string& device, std::vector<Sample>* out, TextLogStats* stats,
                     std::string* error);

// imu_tk's pair of files (time, x, y, z counts each), rows at the same times: the accelerometer's
// and the gyro's, scaled by `acc` and `gyr` (their columns are set here). False with *error when a
// file cannot be read, or the two disagree in rows or times (beyond 1e-6 s).
bool ReadImuTkPair(const std::string& acc_path, const std::string& gyr_path, TriadColumns acc,
                   TriadColumns gyr, const std::string& device, std::vector<Sample>* out,
                   TextLogStats* stats, std::string* error);

}  // namespace turncal::drivers
