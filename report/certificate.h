#pragma once
// The calibration certificate (issue 24, docs/CERTIFICATES.md): one printable HTML page per
// device and calibration -- identity, station, date, environment, procedure, every parameter
// with its standard uncertainty u = sigma and expanded uncertainty U = 2 sigma (coverage factor
// k = 2, about 95 %, as the GUM states it), the gate's tolerance and verdict, the software and a
// content hash. Inline CSS only: no script runs, nothing is fetched, so Chromium prints it as it
// is (`turncal certificate --pdf`).
//
// The content hash is SHA-256 over the file's bytes with every occurrence of the hash's 64 hex
// digits replaced by 64 zeros (kCertificateHashPlaceholder). It is written twice, in
// <meta name="turncal-certificate-sha256" content="..."> and visibly in the footer, so any edit
// -- text, markup, whitespace, the hash itself -- fails VerifyCertificateHtml. It proves that
// the file is what turncal wrote, not who ran turncal: there is no signature.
//
// The certificate's content, in SI units at full precision, is also embedded as
// <script type="application/json" id="turncal-certificate-data"> (a data block, never run), for a
// registry or a script to compare with its records.

#include <nlohmann/json.hpp>
#include <string>

namespace turncal::report {

struct CertificateSource {
  // One calibration document as turncald writes it (calibrations/DEVICE.MODEL.json or
  // history/DEVICE.MODEL.vN.json): a turntable calibration (protocol/calibration_json.h) or a
  // free one (protocol/free_json.h).
  nlohmann::json calibration;
  // The calibration station's name; "" is shown as "unknown".
  std::string station;
  // Where the calibration was read ("state directory /var/lib/turncal", "registry ..."); may be
  // empty.
  std::string source;
  // Identity known besides the device's own dialogue (a registry's serial, model, firmware):
  // keys "serial", "model_name", "firmware", ... fill in or replace
  // provenance.device_identity's. May be null.
  nlohmann::json identity;
  // The unit's drift over its calibrations (issue 39 item 3): the rows of `turncal registry
  // drift --json` (any model's; the certificate keeps its model's, report/drift_section.h).
  // Null: none, and no section.
  nlohmann::json drift;
  // When the certificate was issued, shown as given (rendering reads no clock, so that the same
  // input gives the same bytes); "" leaves it out.
  std::string issued_utc;
};

// 64 zeros: what the hash's own digits are replaced by before hashing.
extern const char* const kCertificateHashPlaceholder;

// "STATION-DEVICE-MODEL-vVERSION", every character outside [A-Za-z0-9._] replaced by '_'.
std::string CertificateNumber(const std::string& station, const std::string& device,
                              const std::string& model, int version);

// The certificate's content (the embedded data block): identity, station, environment,
// procedure, parameters (SI: value, u, U = 2u, tolerance on u, the gate's check), verdict, fit.
// False with a message when the document is not a calibration of a known model with a value for
// each of its parameters.
bool CertificateContent(const CertificateSource& source, nlohmann::json* content,
                        std::string* error);

// The certificate of `source`; *hash_hex is its content hash (64 lower-case hex digits). False
// with a message, outputs untouched, as CertificateContent. Deterministic: the same source gives
// the same bytes.
bool RenderCertificateHtml(const CertificateSource& source, std::string* html,
                           std::string* hash_hex, std::string* error);

struct CertificateCheck {
  bool ok = false;
  // Not a turncal certificate at all (no hash in it): callers tell this from an edited one.
  bool not_a_certificate = false;
  std::string hash_claimed;   // from the <meta>; "" when there is none
  std::string hash_computed;  // over the bytes, the claimed hash replaced by the placeholder
  std::string reason;         // why not ok, in plain words
};

// Recomputes the content hash of `html` and compares it with the one it claims, also the
// visible one: byte for byte, with no normalisation of whitespace or line ends.
CertificateCheck VerifyCertificateHtml(const std::string& html);

// SHA-256 of `bytes` as 64 lower-case hex digits (OpenSSL's EVP interface).
std::string Sha256Hex(const std::string& bytes);

}  // namespace turncal::report
