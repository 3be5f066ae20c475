#pragma once
// `turncal report -o FILE | --state-dir DIR [--device D]`: the HTML calibration report
// (report/html.h) of each device with active calibrations, read from the state
// directory -- DIR, or the running daemon's (its `status` reply names it). One file per device:
// FILE itself for one device; with several and no --device, FILE with the device's name put
// before the extension (report.html -> report.imu1.html). Prints each file written.

#include <string>

namespace turncal::tools {

struct HtmlReportArgs {
  std::string socket;  // asked for the state directory when `state_dir` is empty
  bool json = false;   // one {"class":"REPORT",...} line per file instead of text
  std::string output = "turncal-report.html";
  std::string state_dir;
  std::string device;
  std::string drift;  // a file of `turncal registry drift SERIAL --json`; "" none
};

// 0 when every report was written; 2 with a message on stderr otherwise.
int RunHtmlReport(const HtmlReportArgs& args);

// FILE for `device` when a report covers several devices: the name before the extension.
std::string ReportPathForDevice(const std::string& output, const std::string& device);

}  // namespace turncal::tools
