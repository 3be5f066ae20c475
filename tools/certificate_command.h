#pragma once
// `turncal certificate`: calibration certificates (report/certificate.h, docs/CERTIFICATES.md).
//
//   turncal certificate --state-dir DIR --device NAME [--model M ...] [--version N]
//                       [--station NAME] [--issued DATE] -o OUT.html [--pdf OUT.pdf]
//   turncal certificate --verify FILE.html
//
// One certificate per model: OUT.html itself for one model; with several, OUT.MODEL.html (and
// OUT.MODEL.pdf), the model's name put before the extension. --version N takes
// history/DEVICE.MODEL.vN.json (or the active calibration when it is version N) and needs --model.

#include <CLI/CLI.hpp>
#include <string>

#include "report/certificate.h"

namespace turncal::tools {

void AddCertificateCommand(CLI::App* app);

// Renders `source`'s certificate into `html_out` (written atomically) and, when `pdf_out` is not
// empty, prints it to `pdf_out` with headless Chromium. Prints "FILE<TAB>NUMBER<TAB>sha256 HASH"
// per file written. 0 when done; 2 with a message on stderr (a malformed calibration, a file
// that cannot be written, Chromium missing or failing). For `turncal registry certificate` too.
int WriteCertificate(const report::CertificateSource& source, const std::string& html_out,
                     const std::string& pdf_out);

// Prints `html_path` to `pdf_path` with headless Chromium ($TURNCAL_CHROMIUM, else chromium,
// chromium-browser or google-chrome on PATH): no network, a throw-away profile, no header or
// footer. False with a message when there is no Chromium, it fails or times out, or what it
// wrote is not a PDF.
bool PrintPdfWithChromium(const std::string& html_path, const std::string& pdf_path,
                          std::string* error);

// `turncal certificate --verify FILE`: 0 verified, 1 the hash does not match (edited), 2 the
// file cannot be read or is not a turncal certificate.
int VerifyCertificateFile(const std::string& path);

}  // namespace turncal::tools
