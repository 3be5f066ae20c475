#include "tools/help_text.h"

#include <map>

namespace turncal::tools {
namespace {

struct Manual {
  const char* description;
  const char* examples;
  const char* exit_status;
  const char* see_also;
};

// Client commands share these.
constexpr const char* kClientExit =
    "0 done; 2 the daemon cannot be reached (is turncald running? --socket, $TURNCAL_SOCKET), it "
    "answered ERROR, or a command-line mistake";
constexpr const char* kSocketNote =
    "The daemon's socket is --socket, else $TURNCAL_SOCKET, else /run/turncal/turncal.sock.";

const std::map<std::string, Manual>& Manuals() {
  static const std::map<std::string, Manual> manuals = {
      {"status",
       {"The daemon's state: every device's connection, rates and counters, poses captured, the "
        "pose being collected, each model's gate and active calibration version. {socket}",
        "turncal status\n"
        "turncal status --json | jq '.devices.imu1.counters'",
        kClientExit, "docs/protocol.md (status), docs/TROUBLESHOOTING.md"}},
      {"devices",
       {"The daemon's devices and what they said in their configuration dialogue (identity, "
        "firmware, rate). With --local: this machine's serial ports, no daemon needed. {socket}",
        "turncal devices\n"
        "turncal devices --local          # which /dev/ttyUSB* is which IMU",
        kClientExit, "docs/TROUBLESHOOTING.md (permissions, ModemManager)"}},
      {"result",
       {"The current estimate of every model of every device: each parameter with its 1 sigma, "
        "rank, chi^2 and the publish gate's verdict with its reasons. {socket}",
        "turncal result\n"
        "turncal result --json > result.json   # the shape of turncald --result-out",
        kClientExit, "docs/models.md (what each parameter means), docs/OBSERVABILITY.md"}},
      {"report",
       {"Without -o: status and result together, as text. With -o FILE: the calibration report, "
        "one self-contained HTML file per device (parameter table with 1 sigma and tolerances, "
        "residual, coverage and convergence plots, observability). It reads the active "
        "calibrations from the state directory (--state-dir, else the one the daemon reports). "
        "{socket}",
        "turncal report\n"
        "turncal report -o report.html\n"
        "turncal report --state-dir /var/lib/turncal --device imu1 -o imu1.html   # no daemon",
        "0 done; 2 the daemon cannot be reached, it answered ERROR, no active calibration was "
        "found, a calibration file is unreadable or malformed, --device names no device there, "
        "or a command-line mistake",
        "README.md (the walk-through), docs/models.md; turncald writes "
        "STATE_DIR/reports/DEVICE.html itself after each activation"}},
      {"next-pose",
       {"The most informative pose to capture next for a device (D-optimal over its models), and "
        "how many poses the gate still needs. {socket}",
        "turncal next-pose\n"
        "turncal next-pose --device imu2 --json",
        "0, also when there is no recommendation (printed as \"no recommendation: ...\"); 2 as "
        "for every client command",
        "docs/OBSERVABILITY.md (planning), tools/examples/turntable_controller.py --plan"}},
      {"watch",
       {"Live view: pose progress, poses captured, each parameter's sigma against its tolerance. "
        "On a terminal the view redraws in place; otherwise one line per event (a log). With "
        "--corrected / --raw it also prints samples; --json prints the daemon's messages "
        "unchanged. {socket}",
        "turncal watch\n"
        "turncal watch --corrected --rate 10 --json     # corrected samples for a script\n"
        "turncal watch --seconds 60 > session.log",
        "0 after --count samples or --seconds; 2 on an error or when the daemon closes the "
        "connection",
        "docs/protocol.md (watch, CORRECTED)"}},
      {"pose",
       {"Tells turncald that the table is at PHI GAMMA PSI (degrees: inner x, middle y, outer z "
        "axis) and waits until every device captured or rejected the pose. A controller script "
        "calls this after each move. Negative angles need no --. {socket}",
        "turncal pose 0 0 0\n"
        "turncal pose 90 45 -180 --dwell 5\n"
        "turncal pose 0 90 0 --device imu2 || echo \"rejected or failed: $?\"",
        "0 every device captured the pose; 1 some device rejected it (the reason is printed); 2 "
        "an ERROR, no answer within --timeout, or a command-line mistake",
        "tools/examples/README.md (a whole controller), docs/SEQUENCER.md (why poses are "
        "rejected)"}},
      {"rate",
       {"Tells turncald that the table turns about AXIS (outer, middle or inner) at RATE deg/s, "
        "the other axes at --phi/--gamma/--psi degrees, and waits until every device captured "
        "or rejected the rate segment: once the gyro's rate is steady, turncald averages it over "
        "whole revolutions (at least the dwell) for the gyroscope models (gyro12, gyro21). "
        "A controller calls this once the table turns steadily. {socket}",
        "turncal rate outer 100\n"
        "turncal rate outer -100 --gamma 90\n"
        "turncal rate inner 30 --dwell 20 || echo \"rejected or failed: $?\"",
        "0 every device captured the segment; 1 some device rejected it (the reason is printed: "
        "a rate that is not steady, or not the announced one); 2 an ERROR, no answer within "
        "--timeout, or a command-line mistake",
        "docs/protocol.md (\"rate\"), docs/models.md (\"Gyroscope models\"), docs/SEQUENCER.md "
        "(\"Rate segments\")"}},
      {"reset",
       {"Starts a new session: the current poses and noise profiles are archived under "
        "sessions/ in the state directory; active calibrations stay active. Needs a permitted "
        "uid. {socket}",
        "turncal reset --note \"new fixture\"", kClientExit,
        "systemd/README.md (state directory)"}},
      {"publish",
       {"Operator override: makes the current estimate of DEVICE MODEL active although the gate "
        "refused it. The operator, the reason and the gate's reasons are recorded in the "
        "calibration. Needs a permitted uid. {socket}",
        "turncal publish imu1 accel13 --operator \"A. Engineer\" --reason \"re-issue after audit\"",
        kClientExit, "docs/protocol.md (publish)"}},
      {"device-write",
       {"Writes DEVICE's active calibration of MODEL into the device's stored calibration (MIP: "
        "accelerometer and gyro bias, hard-iron offset, soft-iron matrix), composed with what "
        "it stores now. Shows the plan first: the stored values, the values to write with their "
        "1 sigma, the expected change of the output, what stays in turncald's stream (scale "
        "factors and misalignments, which MIP cannot hold), and every refusal (gate not passed, "
        "another serial, other stored values than the calibration was made with, Xbus, GX2). "
        "With --transform it also writes the sensor-to-vehicle transform (0x33), so that the "
        "device outputs in the frame the calibration corrects into (every output turns). "
        "Then asks (or --yes), writes, reads back bit for bit, saves only with --save, and "
        "verifies by measurement: the device's uncorrected output after the write must be the "
        "output predicted from before it (0.1 % false alarms; a device that moved: at the next "
        "captured pose). A failure rolls back. The replaced "
        "values are kept in the state directory (device_writes/); --restore puts back what the "
        "device held before turncal wrote into it. "
        "Needs a permitted uid. {socket}",
        "turncal device-write imu1 --model mag13 --dry-run\n"
        "turncal device-write imu1 --model mag13 --save\n"
        "turncal device-write imu1 --restore",
        "0 written and verified (or --dry-run: the plan may be written); 1 written but not "
        "verified, not confirmed, or (--dry-run) refused; 2 refused, failed (the device is "
        "as it was, or the reply says its state), the daemon cannot be reached, or a "
        "command-line mistake",
        "docs/protocol.md (Writing a calibration into the device)"}},
      {"registry",
       {"The calibration registry that every station's outbox fills (PostgreSQL; [registry] in "
        "turncald.toml). history SERIAL lists every calibration of a device at every station "
        "(a device that moved between stations shows both); latest SERIAL shows its latest "
        "passing calibration of each model with the parameters and their sigma; export writes "
        "CSV (one row per calibration and parameter) or JSON (whole documents with the writes "
        "into the device); stations shows each station's last contact; certificate SERIAL "
        "--model M writes the calibration certificate of its latest passing (or --version N) "
        "calibration (docs/CERTIFICATES.md) and records it with its hash; verify FILE checks that "
        "a "
        "certificate is unchanged and that the registry issued it; migrate brings the schema to "
        "this turncal's "
        "version. The connection: --db, else TURNCAL_REGISTRY, else "
        "--config's [registry] (the password from its password_file).",
        "turncal registry history 6251.12345 --db 'host=db.lab dbname=turncal'\n"
        "turncal registry latest 6251.12345 --model accel13 --json\n"
        "turncal registry export --format csv --passing -o calibrations.csv\n"
        "turncal registry stations --config /etc/turncal/turncald.toml\n"
        "turncal registry certificate 6251.12345 --model mag13 -o cert.html --pdf cert.pdf\n"
        "turncal registry verify cert.html",
        "0 done (verify: unchanged and issued by the registry); 1 nothing found (history, "
        "latest, certificate), or verify: edited or not issued by the registry; 2 the registry "
        "cannot be reached, refused the query, or a command-line mistake",
        "docs/REGISTRY.md, README (A registry for several stations)"}},
      {"certificate",
       {"The calibration certificate of a device's calibration, one printable HTML file per "
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
        "docs/CERTIFICATES.md, docs/models.md (the parameters)"}},
      {"capture",
       {"Records a live port into a .tcap capture (bytes with their host times) until Ctrl-C or "
        "SIGTERM. A capture replays through the whole pipeline: turncald --replay FILE --once.",
        "turncal capture --device imu=mip:/dev/ttyUSB0@921600 -o session.tcap\n"
        "turncal capture --device imu=xbus:tcp://10.0.0.5:4001 -o xsens.tcap --note \"bench 2\"",
        "0 when stopped by a signal; 1 the port failed; 2 a command-line mistake",
        "docs/capture-format.md"}},
      {"decode",
       {"Decodes a capture or a raw byte stream: frames and samples (SI units), then one SUMMARY "
        "line with the counters (frames, samples, bad checksums, skipped bytes).",
        "turncal decode session.tcap | tail -1\n"
        "turncal decode stream.bin --protocol mip --json | head",
        "0 decoded (bad frames are counted, not fatal); 2 the input cannot be read or a "
        "command-line mistake",
        "docs/DRIVERS.md, docs/TROUBLESHOOTING.md (baud rate)"}},
      {"models",
       {"Lists the measurement models and their parameters in the order results use.",
        "turncal models\nturncal models --json", "0", "docs/models.md"}},
      {"fit-sim",
       {"Simulates one calibration session in memory, calibrates it and prints every parameter "
        "with its 1 sigma, the truth and the error in sigma units.",
        "turncal fit-sim --model accel13 --poses 26 --design cube\n"
        "turncal fit-sim --model mag22 --class consumer --seed 7 --json",
        "0; 2 a command-line mistake", "docs/ACCURACY.md"}},
      {"montecarlo",
       {"Repeats simulated sessions and checks that the reported sigma matches the scatter of the "
        "errors (the honesty of the uncertainty).",
        "turncal montecarlo --model accel13 --runs 1000\n"
        "turncal montecarlo --model mag13 --noise session --runs 200\n"
        "turncal montecarlo --pipeline --model accel13 --class consumer --protocol xbus --plan "
        "shuffled --runs 200   # sessions as bytes through the station, as turncald --replay "
        "--once runs them",
        "0 every criterion holds; 1 one does not (a parameter's std z outside [0.9, 1.1] or "
        "|mean z| > 0.15, chi^2 p-values not uniform, a run without an estimate); 2 a "
        "command-line mistake",
        "docs/ACCURACY.md"}},
      {"free",
       {"Calibrates without a turntable: a tumble by hand or on a fixture with unknown angles. "
        "The sequencer finds the static intervals itself (free mode: its stillness thresholds "
        "from the noise it measures, or from --sensor-class), then fits the free models -- "
        "accel9 (|f| = g), gyro9 (the gyro's turn between intervals against gravity's direction; "
        "gyro9g adds the g-sensitivity), magellipsoid (hard and soft iron; magsphere when the "
        "data cannot carry an ellipsoid, with the reason), accmag (the rotation between the "
        "magnetometer and the accelerometer from the constant dip) -- each with 1 sigma, the "
        "chi^2 fit check, the rank and its weakest direction, the spatial coverage (MicroStrain's "
        "18 x 32 bins), the gate and the next orientation to add. Inputs: a .tcap capture (its "
        "pose events ignored), a raw device stream (--protocol; --rate when it carries no "
        "clock), a text or CSV log (--columns, per-triad --*-offset and --*-scale), or imu_tk's "
        "two .mat files.",
        "turncal free tumble.tcap --intervals\n"
        "turncal free xsens_acc.mat xsens_gyro.mat --acc-offset 32768 --acc-scale 0.0026391 "
        "--gyr-offset 32768 --gyr-scale 0.0001598 --gravity 9.81744 --models accel9,gyro9g\n"
        "turncal free log.csv --columns t,ax,ay,az,mx,my,mz --field 0.5 --html report.html\n"
        "turncal free compass.bin --protocol mip --rate 50 --sensor-class consumer",
        "0 every model fitted and passed its gate; 1 a model was refused or could not be fitted; "
        "2 the input cannot be read or a command-line mistake",
        "docs/FREE.md, docs/ACCURACY.md (\"Without a turntable\")"}},
      {"free-montecarlo",
       {"Repeats simulated tumbles (random orientations of a three-axis table, as bytes, the "
        "announced poses ignored) through free mode, and checks a free model's sigma against "
        "its errors: mean and std of z per parameter, the count beyond 3 sigma, the chi^2 "
        "p-values against uniform, the gate.",
        "turncal free-montecarlo --model accel9 --runs 200\n"
        "turncal free-montecarlo --model gyro9 --class consumer --runs 200\n"
        "turncal free-montecarlo --model magellipsoid --cap 20 --runs 50   # low coverage",
        "0 every parameter's std z in [0.9, 1.1] with |mean z| <= 0.15; 1 otherwise, or no run "
        "gave an estimate; 2 a command-line mistake",
        "docs/ACCURACY.md (\"Without a turntable\")"}},
      {"noise",
       {"The overlapping Allan deviation of a static recording, per triad and axis, and the noise "
        "model fitted to it: white-noise density N, a Gauss-Markov bias instability (sigma, tau), "
        "a random walk, and the IEEE flat-bottom figure. Record the sensor at rest for several "
        "times the longest correlation time you care about; use --from/--to to keep only the "
        "rest. The fitted values go into turncald.toml's [station] as the noise prior: "
        "acc_noise_density, acc_bias_instability (GM sigma), bias_tau_s (GM tau), acc_random_walk "
        "and the mag_ equivalents (docs/ACCURACY.md \"Drift\").",
        "turncal noise rest.tcap --svg rest-allan.svg\n"
        "turncal noise imu.bin --protocol mip --to 600 --json\n"
        "turncal noise xsens_acc.mat --triad acc --to 45   # imu_tk's text columns (raw counts)",
        "0 done; 1 no triad with enough samples, or the plot cannot be written; 2 the input "
        "cannot be read or a command-line mistake",
        "docs/ACCURACY.md (the noise model), SENSORS.md"}},
      {"sim",
       {"Simulates a whole turntable session: a .tcap capture of a MIP, GX2 or Xbus device and a "
        "truth file. With --live it streams into ptys in real time (or --live-speed times "
        "faster); with --controller it also plays the lab's controller on turncald's socket.",
        "turncal sim --protocol mip --seed 1 --truth-out truth.json -o session.tcap\n"
        "turncal sim --protocol xbus --live /tmp/imu --poses poses.csv --live-speed 2\n"
        "turncal sim --protocol mip --protocol xbus --live /tmp/a /tmp/b --controller "
        "/run/turncal/turncal.sock",
        "0 written (with --controller: every pose captured); 1 some pose was not captured or a "
        "write failed; 2 a command-line mistake",
        "docs/SIMULATOR.md"}},
      {"poses",
       {"Prints a pose list (CSV, degrees) of a standard design, for --poses FILE of the other "
        "commands and for a controller script.",
        "turncal poses --design cube > cube.csv\nturncal poses --design random --count 40 --seed 3",
        "0; 2 a command-line mistake", "docs/OBSERVABILITY.md"}},
      {"observability",
       {"Rank, null directions (in parameter names) and Cramer-Rao sigma of a model: the paper's "
        "structural test, or the data-level test over a pose list.",
        "turncal observability --model mag22 --structural\n"
        "turncal observability --model accel13 --poses cube.csv --json",
        "0; 2 a command-line mistake or an unreadable pose list", "docs/OBSERVABILITY.md"}},
      {"plan",
       {"The D-optimal next pose over a grid of reachable table angles, and the greedy plan until "
        "the predicted publish gate passes.",
        "turncal plan --model accel13 --model mag13\n"
        "turncal plan --poses captured.csv --gamma -60:60:30 --json",
        "0; 2 a command-line mistake or an unreadable pose list", "docs/OBSERVABILITY.md"}},
      {"plan-vs-cube",
       {"Simulated sessions: how many poses the real calibrator and gate need along the 26-pose "
        "cube and with next-pose planning.",
        "turncal plan-vs-cube --model accel13 --class consumer --runs 50",
        "0; 2 a command-line "
        "mistake",
        "docs/OBSERVABILITY.md"}},
      {"sequence",
       {"Replays a capture through the decoders and the position sequencer only: which poses were "
        "captured or rejected, and why. Useful to tune stillness settings on a real recording.",
        "turncal sequence session.tcap\n"
        "turncal sequence table.tcap --schedule poses.csv --dwell 5 --json",
        "0; 2 the capture cannot be read or a command-line mistake", "docs/SEQUENCER.md"}},
  };
  return manuals;
}

// Words of `text` in lines of at most `width` characters, each indented by two spaces.
std::string Wrap(const std::string& text, std::size_t width = 96) {
  std::string out, line;
  std::size_t start = 0;
  while (start < text.size()) {
    std::size_t end = text.find(' ', start);
    if (end == std::string::npos) end = text.size();
    const std::string word = text.substr(start, end - start);
    if (!line.empty() && line.size() + 1 + word.size() > width) {
      out += "  " + line + "\n";
      line.clear();
    }
    if (!word.empty()) line += (line.empty() ? "" : " ") + word;
    start = end + 1;
  }
  if (!line.empty()) out += "  " + line + "\n";
  return out;
}

std::string Render(const Manual& m) {
  std::string description = m.description;
  const std::string token = "{socket}";
  if (auto at = description.find(token); at != std::string::npos) {
    description.replace(at, token.size(), kSocketNote);
  }
  std::string examples;
  std::string line;
  for (const char* c = m.examples;; ++c) {
    if (*c == '\n' || *c == '\0') {
      examples += "  $ " + line + "\n";
      line.clear();
      if (*c == '\0') break;
    } else {
      line += *c;
    }
  }
  return "\nDESCRIPTION\n" + Wrap(description) + "\nEXAMPLES\n" + examples + "\nEXIT STATUS\n" +
         Wrap(m.exit_status) + "\nSEE ALSO\n" + Wrap(m.see_also);
}

}  // namespace

std::string ManualFooter(const std::string& subcommand) {
  const auto it = Manuals().find(subcommand);
  return it == Manuals().end() ? std::string() : Render(it->second);
}

std::vector<std::string> AddManualFooters(CLI::App* app) {
  std::vector<std::string> missing;
  for (CLI::App* sub : app->get_subcommands([](CLI::App*) { return true; })) {
    const std::string text = ManualFooter(sub->get_name());
    if (text.empty()) {
      missing.push_back(sub->get_name());
      continue;
    }
    sub->footer(text);
  }
  return missing;
}

}  // namespace turncal::tools
