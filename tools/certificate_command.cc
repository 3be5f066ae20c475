#include "tools/certificate_command.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <thread>
#include <vector>

#include "daemon/state/atomic_file.h"
#include "daemon/state/state_dir.h"
#include "drivers/transport/transport.h"
#include "tools/help_text.h"
#include "tools/report_state_dir.h"

namespace turncal::tools {
namespace fs = std::filesystem;

namespace {

// The codes CertFail, RunCertificateCommand and VerifyCertificateFile return.
constexpr Manual kCertificateManual = {
    "The calibration certificate of a device's calibration, one printable HTML file per "
    "model (and with --pdf a PDF printed by headless Chromium): identity (serial, model, "
    "firmware), station, date, environment (reference gravity and field), procedure (poses, "
    "dwell, rates, noise model), every parameter with its standard uncertainty u = 1 sigma, "
    "its expanded uncertainty U = 2u (k = 2, about 95 %, GUM) and the gate's tolerance on u, "
    "the verdict, the software and a SHA-256 content hash. It reads the active calibration "
    "(STATE_DIR/calibrations/DEVICE.MODEL.json) or, with --version, an earlier one "
    "(history/). --verify recomputes the hash: any edit of the file fails. The same "
    "calibration gives the same file (no date is added unless --issued).",
    "turncal certificate --state-dir /var/lib/turncal --device imu1 --station lab-2 -o "
    "cert.html   # cert.accel13.html, cert.mag13.html, ...\n"
    "turncal certificate --state-dir /var/lib/turncal --device imu1 --model accel13 "
    "--version 4 -o imu1-v4.html --pdf imu1-v4.pdf\n"
    "turncal certificate --verify cert.accel13.html",
    "0 written (or --verify: the hash matches); 1 --verify: the file was changed after "
    "turncal wrote it; 2 no such calibration, a malformed calibration, a file that cannot "
    "be written, Chromium missing or failing (--pdf), an unreadable file or not a "
    "certificate (--verify), or a command-line mistake",
    "docs/CERTIFICATES.md, docs/models.md (the parameters)"};

int CertFail(const std::string& message) {
  fmt::print(stderr, "turncal certificate: {}\n", message);
  return 2;
}

bool CertReadFile(const std::string& path, std::string* text) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  std::stringstream s;
  s << in.rdbuf();
  *text = s.str();
  return !in.bad();
}

// OUT.html -> OUT.MODEL.html when one command writes several certificates.
std::string CertPathForModel(const std::string& path, const std::string& model) {
  const fs::path p(path);
  return (p.parent_path() / (p.stem().string() + "." + model + p.extension().string())).string();
}

// Chromium: $TURNCAL_CHROMIUM, else the first of the usual names on PATH.
std::string CertFindChromium() {
  if (const char* env = std::getenv("TURNCAL_CHROMIUM"); env && *env) return env;
  const char* path = std::getenv("PATH");
  std::stringstream dirs(path ? path : "/usr/bin:/bin");
  std::string dir;
  while (std::getline(dirs, dir, ':')) {
    for (const char* name : {"chromium", "chromium-browser", "google-chrome"}) {
      const fs::path candidate = fs::path(dir.empty() ? "." : dir) / name;
      if (access(candidate.c_str(), X_OK) == 0) return candidate.string();
    }
  }
  return "";
}

// file:///abs/path with the characters a URL reserves percent-encoded.
std::string CertFileUrl(const std::string& path) {
  std::string url = "file://";
  for (unsigned char ch : fs::absolute(path).lexically_normal().string()) {
    if (std::isalnum(ch) ||
        std::string_view("/-._~").find(static_cast<char>(ch)) != std::string_view::npos) {
      url += static_cast<char>(ch);
    } else {
      url += fmt::format("%{:02X}", ch);
    }
  }
  return url;
}

// Runs `argv` with stdout and stderr into `log`; its exit status, or -1 when it could not be
// started or was killed after `timeout`.
int CertRun(const std::vector<std::string>& argv, const std::string& log,
            std::chrono::seconds timeout) {
  std::vector<char*> args;
  args.reserve(argv.size() + 1);
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  const pid_t pid = fork();
  if (pid < 0) return -1;
  if (pid == 0) {
    const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
      dup2(fd, STDOUT_FILENO);
      dup2(fd, STDERR_FILENO);
    }
    execvp(args[0], args.data());
    _exit(127);
  }
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  int status = 0;
  while (waitpid(pid, &status, WNOHANG) == 0) {
    if (std::chrono::steady_clock::now() > deadline) {
      kill(pid, SIGKILL);  // our own child, by its id
      waitpid(pid, &status, 0);
      return -1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string CertLogTail(const std::string& log) {
  std::string text;
  CertReadFile(log, &text);
  if (text.size() > 600) text = "..." + text.substr(text.size() - 600);
  return text;
}

struct CertificateArgs {
  std::string state_dir, device, output, pdf, station, issued, verify;
  std::string drift;  // a file of `turncal registry drift SERIAL --json`
  std::vector<std::string> models;
  int version = 0;
};

// The calibrations the arguments name: the active ones, or version N from history/.
bool CertCollect(const CertificateArgs& a, std::vector<nlohmann::json>* out, std::string* error) {
  if (a.version > 0) {
    if (a.models.empty()) {
      *error = "--version needs --model (each model has its own versions)";
      return false;
    }
    for (const auto& model : a.models) {
      const daemon::StateDir places(a.state_dir);
      std::string text;
      std::string path = places.ActiveCalibration(a.device, model).string();
      nlohmann::json j;
      if (CertReadFile(path, &text)) j = nlohmann::json::parse(text, nullptr, false);
      if (!j.is_object() || !j.contains("version") || j["version"] != a.version) {
        path = places.HistoryCalibration(a.device, model, a.version).string();
        if (!CertReadFile(path, &text)) {
          *error = fmt::format("no version {} of {} {} ('{}' cannot be read)", a.version, a.device,
                               model, path);
          return false;
        }
        j = nlohmann::json::parse(text, nullptr, false);
      }
      if (!j.is_object()) {
        *error = fmt::format("'{}' is not valid JSON", path);
        return false;
      }
      out->push_back(std::move(j));
    }
    return true;
  }
  std::map<std::string, DeviceCalibrations> devices;
  if (!ReadStateDirCalibrations(a.state_dir, a.device, &devices, error)) return false;
  DeviceCalibrations& d = devices.begin()->second;
  for (const auto& model : a.models) {
    const bool found = std::any_of(d.calibrations.begin(), d.calibrations.end(),
                                   [&](const auto& c) { return c.value("model", "") == model; });
    if (!found) {
      *error = fmt::format("{} has no active calibration of model {}", a.device, model);
      return false;
    }
  }
  for (std::size_t i = 0; i < d.calibrations.size(); ++i) {
    const std::string model = d.calibrations[i].value("model", "");
    if (!a.models.empty() && std::find(a.models.begin(), a.models.end(), model) == a.models.end()) {
      continue;
    }
    // Documents older than provenance.records: the journal's, for the dwell and temperature.
    const std::string note = AttachJournalRecords(a.state_dir, &d.calibrations[i]);
    if (!note.empty()) fmt::print(stderr, "turncal certificate: {}: {}\n", d.paths[i], note);
    out->push_back(d.calibrations[i]);
  }
  return true;
}

int RunCertificateCommand(const CertificateArgs& a) {
  if (!a.verify.empty()) return VerifyCertificateFile(a.verify);
  if (a.state_dir.empty() || a.device.empty() || a.output.empty()) {
    return CertFail("give --state-dir, --device and -o (or --verify FILE)");
  }
  std::vector<nlohmann::json> calibrations;
  std::string error;
  if (!CertCollect(a, &calibrations, &error)) return CertFail(error);
  const bool several = calibrations.size() > 1;
  for (const auto& c : calibrations) {
    report::CertificateSource source;
    source.calibration = c;
    source.station = a.station;
    source.source = "state directory " + a.state_dir;
    source.issued_utc = a.issued == "now" ? drivers::UtcNowIso8601() : a.issued;
    if (!a.drift.empty() && !ReadDriftFile(a.drift, &source.drift, &error)) return CertFail(error);
    const std::string model = c.value("model", "");
    const std::string html = several ? CertPathForModel(a.output, model) : a.output;
    const std::string pdf = a.pdf.empty() || !several ? a.pdf : CertPathForModel(a.pdf, model);
    if (const int rc = WriteCertificate(source, html, pdf); rc != 0) return rc;
  }
  return 0;
}

}  // namespace

bool PrintPdfWithChromium(const std::string& html_path, const std::string& pdf_path,
                          std::string* error) {
  const std::string chromium = CertFindChromium();
  if (chromium.empty() || access(chromium.c_str(), X_OK) != 0) {
    *error = fmt::format(
        "--pdf needs Chromium, and {} (apt-get install chromium, or set TURNCAL_CHROMIUM); the "
        "HTML certificate is written",
        chromium.empty() ? "there is none on PATH" : "'" + chromium + "' cannot be run");
    return false;
  }
  char profile_template[] = "/tmp/turncal-chromium-XXXXXX";
  const char* profile = mkdtemp(profile_template);
  if (!profile) {
    *error = "cannot make a temporary folder for Chromium's profile";
    return false;
  }
  const std::string log = std::string(profile) + "/chromium.log";
  std::error_code ec;
  fs::remove(pdf_path, ec);  // so that a PDF left from before is not taken for this one
  const std::vector<std::string> argv = {chromium,
                                         "--headless",
                                         "--no-sandbox",
                                         "--disable-gpu",
                                         "--disable-dev-shm-usage",
                                         "--disable-quic",
                                         "--no-first-run",
                                         "--disable-background-networking",
                                         "--disable-component-update",
                                         "--disable-sync",
                                         std::string("--user-data-dir=") + profile + "/profile",
                                         "--print-to-pdf=" + fs::absolute(pdf_path).string(),
                                         "--no-pdf-header-footer",
                                         CertFileUrl(html_path)};
  // Chromium takes a few seconds on a loaded machine; two minutes means it hangs.
  const int rc = CertRun(argv, log, std::chrono::seconds(120));
  std::string head;
  std::ifstream pdf(pdf_path, std::ios::binary);
  head.resize(5);
  const bool is_pdf = pdf && pdf.read(head.data(), 5) && head == "%PDF-";
  if (rc != 0 || !is_pdf) {
    *error = fmt::format("Chromium ({}) did not print '{}'{}: {}", chromium, pdf_path,
                         rc < 0 ? " (failed to start or timed out)" : fmt::format(" (exit {})", rc),
                         CertLogTail(log));
  }
  fs::remove_all(profile, ec);
  return rc == 0 && is_pdf;
}

int WriteCertificate(const report::CertificateSource& source, const std::string& html_out,
                     const std::string& pdf_out) {
  std::string html, hash, error;
  if (!report::RenderCertificateHtml(source, &html, &hash, &error)) return CertFail(error);
  if (!daemon::WriteFileAtomically(html_out, html, &error)) return CertFail(error);
  const std::string number = report::CertificateNumber(
      source.station, source.calibration.value("device", ""), source.calibration.value("model", ""),
      source.calibration.value("version", 0));
  fmt::print("{}\t{}\tsha256 {}\n", html_out, number, hash);
  if (pdf_out.empty()) return 0;
  if (!PrintPdfWithChromium(html_out, pdf_out, &error)) return CertFail(error);
  fmt::print("{}\t{}\tprinted by Chromium\n", pdf_out, number);
  return 0;
}

int VerifyCertificateFile(const std::string& path) {
  std::string html;
  if (!CertReadFile(path, &html)) return CertFail(fmt::format("cannot read '{}'", path));
  const report::CertificateCheck check = report::VerifyCertificateHtml(html);
  if (check.not_a_certificate) return CertFail(fmt::format("'{}': {}", path, check.reason));
  if (!check.ok) {
    fmt::print("FAILED: {}: {}\n  claimed  {}\n  computed {}\n", path, check.reason,
               check.hash_claimed, check.hash_computed);
    return 1;
  }
  fmt::print("verified: {}: sha256 {}\n", path, check.hash_computed);
  return 0;
}

void AddCertificateCommand(CLI::App* app) {
  auto args = std::make_shared<CertificateArgs>();
  auto* c = app->add_subcommand(
      "certificate",
      "calibration certificate (HTML, PDF) of a device's calibration, with a content hash; "
      "--verify checks one");
  SetManual(c, kCertificateManual);
  c->add_option("--state-dir", args->state_dir, "the state directory of turncald (calibrations/)");
  c->add_option("--device", args->device, "the device, as turncald names it");
  c->add_option("--model", args->models,
                "only this model (repeatable; default: every model with an active calibration)");
  c->add_option("--version", args->version,
                "the calibration version N (history/DEVICE.MODEL.vN.json); needs --model")
      ->check(CLI::PositiveNumber);
  c->add_option("--station", args->station,
                "the calibration station's name, on the certificate and in its number (default: "
                "unknown)");
  c->add_option("--issued", args->issued,
                "the issue date to print, as given, or \"now\" (UTC); default: none, so that the "
                "same calibration gives the same file");
  c->add_option("-o,--output", args->output,
                "the HTML certificate; with several models, one file each with the model's name "
                "before the extension (cert.html -> cert.accel13.html)");
  c->add_option("--pdf", args->pdf, "also print it to this PDF with headless Chromium");
  c->add_option("--drift", args->drift,
                "the unit's drift over its calibrations, a file of `turncal registry drift SERIAL "
                "--json` (`turncal registry certificate` reads it from the registry itself)");
  auto* verify = c->add_option("--verify", args->verify,
                               "check FILE's content hash: exit 0 verified, 1 changed since "
                               "turncal wrote it, 2 unreadable or not a certificate");
  for (const char* other : {"--state-dir", "--device", "--model", "--version", "--station",
                            "--issued", "-o", "--pdf"}) {
    verify->excludes(c->get_option(other));
  }
  c->callback([args] { throw CLI::RuntimeError(RunCertificateCommand(*args)); });
}

}  // namespace turncal::tools
