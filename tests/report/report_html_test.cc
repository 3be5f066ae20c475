// The calibration report (report/html.h) on calibrations the station wrote from
// simulated sessions: the document is well formed, self-contained and script-free, every plot is
// there with its id, the parameter table holds every parameter with the stored estimate, the
// residuals shrink by the factor the records themselves give, and malformed calibrations are
// refused with a message.

#include "report/html.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <regex>

#include "core/modeling/measurement_model.h"
#include "daemon/state/persistence.h"
#include "daemon/station/station.h"
#include "protocol/sequencer_json.h"
#include "sim/capture.h"
#include "sim/session_sim.h"
#include "sim/synthetic.h"

namespace turncal {
namespace {

struct Session {
  std::string dir;
  std::vector<nlohmann::json> calibrations;  // one per model
  Eigen::VectorXd accel_truth, gyro_truth;
};

// A simulated session replayed through the station into a state directory; models whose gate
// did not pass are published by operator override, so every model has a calibration.
Session RunSession(const std::string& stem, drivers::Protocol protocol,
                   const std::string& accel_model, const std::string& mag_model, std::uint64_t seed,
                   const std::string& gyro_model = "", bool rate_segments = true) {
  sim::SimCaptureOptions o;
  o.protocol = protocol;
  o.accel_model = accel_model;
  o.mag_model = mag_model;
  o.gyro_model = gyro_model;
  o.poses = CubePoses26();
  if (!gyro_model.empty() && rate_segments) {
    for (const auto& r : DefaultRateSegments()) o.poses.push_back(r);
  }
  o.session.seed = seed;
  sim::SimCapture c;
  std::string error;
  EXPECT_TRUE(sim::BuildSimCapture(o, &c, &error)) << error;
  Session s;
  s.dir = ::testing::TempDir() + "report_" + stem + "_" + std::to_string(::getpid());
  std::filesystem::remove_all(s.dir);
  const std::string path = s.dir + ".tcap";
  {
    auto writer = drivers::CaptureWriter::Create(path, c.header, &error);
    EXPECT_TRUE(writer) << error;
    for (const auto& r : c.records) writer->Append(r.type, r.device, r.t_ns, r.payload, &error);
    EXPECT_TRUE(writer->Close(&error)) << error;
  }
  s.accel_truth = c.session.accel_truth;
  s.gyro_truth = c.session.gyro_truth;
  daemon::StationOptions so;
  so.state_dir = s.dir;
  so.models = {accel_model, mag_model};
  if (!gyro_model.empty()) so.models.push_back(gyro_model);
  daemon::Station station({"imu"}, so, nullptr);
  drivers::CaptureReader reader;
  EXPECT_TRUE(reader.Open(path, &error)) << error;
  daemon::ReplayStats stats;
  EXPECT_TRUE(daemon::ReplayInto(&reader, &station, true, {}, &stats, &error)) << error;
  for (const auto& model : so.models) {
    nlohmann::json stored;
    if (!daemon::ReadActiveCalibration(s.dir, "imu", model, &stored)) {
      EXPECT_TRUE(station.PublishOverride(
          "imu", model, {{"operator", "report test"}, {"reason", "a plot of every model"}}, &error))
          << error;
      EXPECT_TRUE(daemon::ReadActiveCalibration(s.dir, "imu", model, &stored)) << model;
    }
    s.calibrations.push_back(stored);
  }
  std::remove(path.c_str());
  return s;
}

// The sessions are made when a test first asks for them: ctest runs each test in its own
// process, and the second (MIP at 500 Hz) is most of the cost, which the tests that need only the
// first do not pay (under the sanitizers the malformed-input test took 73 s with both, 2026-11-25).
class CalibrationReport : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { sessions_ = new std::vector<Session>; }
  static void TearDownTestSuite() {
    for (const auto& s : *sessions_) std::filesystem::remove_all(s.dir);
    delete sessions_;
  }
  // The first `n` sessions: accel13 + mag13 on Xbus, then accel12 + mag22 on MIP.
  static const std::vector<Session>& Sessions(std::size_t n = 2) {
    if (sessions_->size() < 1 && n >= 1) {
      sessions_->push_back(RunSession("a13", drivers::Protocol::kXbus, "accel13", "mag13", 7));
    }
    if (sessions_->size() < 2 && n >= 2) {
      sessions_->push_back(RunSession("a12", drivers::Protocol::kMip, "accel12", "mag22", 8));
    }
    return *sessions_;
  }
  static std::vector<Session>* sessions_;
};
std::vector<Session>* CalibrationReport::sessions_ = nullptr;

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

// Tags nest and close (void elements and <.../> excepted); the text between them holds no raw
// '<'. Returns "" or what is wrong.
std::string CheckWellFormed(const std::string& html) {
  static const std::vector<std::string> kVoid = {"meta", "br", "hr", "img", "link", "input"};
  std::vector<std::string> open;
  std::size_t i = 0;
  while ((i = html.find('<', i)) != std::string::npos) {
    const std::size_t end = html.find('>', i);
    if (end == std::string::npos) return "a tag is not closed at " + std::to_string(i);
    const std::string tag = html.substr(i + 1, end - i - 1);
    i = end + 1;
    if (tag.empty() || tag[0] == '!') continue;  // doctype
    if (tag[0] == '/') {
      const std::string name = tag.substr(1);
      if (open.empty() || open.back() != name) {
        return "</" + name + "> closes <" + (open.empty() ? "nothing" : open.back()) + ">";
      }
      open.pop_back();
      continue;
    }
    const std::string name = tag.substr(0, tag.find_first_of(" \t\n/"));
    if (name.empty() ||
        !std::all_of(name.begin(), name.end(), [](char c) { return std::isalnum(c); })) {
      return "a raw '<' in the text before '" + tag.substr(0, 20) + "'";
    }
    if (tag.back() == '/' || std::count(kVoid.begin(), kVoid.end(), name)) continue;
    open.push_back(name);
  }
  return open.empty() ? "" : "<" + open.back() + "> is never closed";
}

// An on...= attribute in some tag (script by another name).
bool HasEventHandlerAttribute(const std::string& html) {
  const std::regex handler("\\son[a-z]+\\s*=");
  for (std::size_t i = 0; (i = html.find('<', i)) != std::string::npos; ++i) {
    const std::string tag = html.substr(i, html.find('>', i) - i);
    if (std::regex_search(tag, handler)) return true;
  }
  return false;
}

// The data-* attribute `key` of the element with id `id` (full precision), NaN when absent.
double DataAttribute(const std::string& html, const std::string& id, const std::string& key) {
  const std::size_t at = html.find("id=\"" + id + "\"");
  if (at == std::string::npos) return std::nan("");
  const std::size_t tag_end = html.find('>', at);
  const std::string tag = html.substr(at, tag_end - at);
  std::smatch m;
  if (!std::regex_search(tag, m, std::regex(key + "=\"([^\"]*)\""))) return std::nan("");
  return m[1].str().empty() ? std::nan("") : std::stod(m[1].str());
}

TEST_F(CalibrationReport, IsOneWellFormedScriptFreeDocumentWithEveryPlotAndParameter) {
  for (const Session& s : Sessions()) {
    std::string html, error;
    const auto start = std::chrono::steady_clock::now();
    ASSERT_TRUE(report::RenderReportHtml(
        s.calibrations, {s.dir, "2030-01-01T00:00:00Z", {}, {}, {}}, &html, &error))
        << error;
    const double render_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    std::printf("report of %zu models: %zu bytes, rendered in %.0f ms\n", s.calibrations.size(),
                html.size(), render_ms);
    // TURNCAL_REPORT_OUT=DIR keeps the reports to look at.
    if (const char* keep = std::getenv("TURNCAL_REPORT_OUT")) {
      std::ofstream(std::string(keep) + "/" + s.calibrations[1]["model"].get<std::string>() +
                    ".html")
          << html;
    }
    EXPECT_EQ(html.rfind("<!DOCTYPE html>", 0), 0u);
    EXPECT_NE(html.find("<html lang=\"en\">"), std::string::npos);
    EXPECT_EQ(CheckWellFormed(html), "");
    const std::string lower = Lower(html);
    EXPECT_EQ(lower.find("<script"), std::string::npos);
    EXPECT_FALSE(HasEventHandlerAttribute(lower));
    EXPECT_EQ(lower.find("src="), std::string::npos);  // nothing fetched
    EXPECT_EQ(lower.find("href=\"http"), std::string::npos);
    EXPECT_EQ(lower.find("url("), std::string::npos);
    for (const auto& c : s.calibrations) {
      const std::string model = c["model"];
      for (const char* kind : {"residuals", "coverage", "convergence"}) {
        const std::string open =
            "<svg class=\"plot\" id=\"" + std::string(kind) + "-" + model + "\"";
        const std::size_t at = html.find(open);
        ASSERT_NE(at, std::string::npos) << open;
        const std::string plot = html.substr(at, html.find("</svg>", at) - at);
        EXPECT_EQ(plot.find("<title", plot.find('>')), plot.find('>') + 1) << open << ": <title>";
        EXPECT_EQ(plot.find("class=\"missing\""), std::string::npos) << open << ": data missing";
      }
      std::string error2;
      auto m = MakeModel(model, ModelContext{}, &error2);
      ASSERT_TRUE(m) << error2;
      for (const auto& p : m->parameters()) {
        const std::string id = "param-" + model + "-" + p.name;
        const double value = DataAttribute(html, id, "data-value");
        const double stored = c["params"][p.name]["value"];
        EXPECT_NEAR(value, stored, 1e-15 * std::max(1.0, std::abs(stored))) << id;
        const auto& sigma = c["params"][p.name]["sigma"];
        if (sigma.is_number()) {
          EXPECT_NEAR(DataAttribute(html, id, "data-sigma"), sigma.get<double>(),
                      1e-15 * sigma.get<double>())
              << id;
        }
      }
      EXPECT_NE(html.find(c["gate"]["pass"].get<bool>() ? "<strong>PASS</strong>"
                                                        : "<strong>FAIL</strong>"),
                std::string::npos);
      if (model == "mag22") {
        EXPECT_FALSE(c["gauge"].get<std::string>().empty());
        EXPECT_NE(html.find("Gauge:</strong> " + c["gauge"].get<std::string>()), std::string::npos);
      }
      // This model's observability table names its weakest direction (searched from the table
      // on, up to the next model's section).
      const std::size_t table = html.find("id=\"observability-" + model + "\"");
      ASSERT_NE(table, std::string::npos) << model;
      const std::size_t next = html.find("<h2", table);
      const std::size_t weakest = html.find("weakest direction", table);
      EXPECT_TRUE(weakest != std::string::npos && (next == std::string::npos || weakest < next))
          << model;
    }
  }
}

// The residual RMS before (nominal parameters) and after (the estimate), computed here from the
// calibration's own records with the model's prediction, is what the report states, and the
// calibration reduces it by at least a factor 10 on these sessions.
TEST_F(CalibrationReport, ResidualRmsShrinksByTheFactorTheRecordsGive) {
  for (const Session& s : Sessions()) {
    std::string html, error;
    ASSERT_TRUE(report::RenderReportHtml(s.calibrations, {}, &html, &error)) << error;
    for (const auto& c : s.calibrations) {
      const std::string model_name = c["model"];
      auto model = MakeModel(model_name, ModelContext{}, &error);
      ASSERT_TRUE(model) << error;
      Eigen::VectorXd theta(model->num_parameters());
      for (int i = 0; i < model->num_parameters(); ++i) {
        theta[i] = c["params"][model->parameters()[static_cast<std::size_t>(i)].name]["value"];
      }
      const bool accel = model->sensor() == SensorKind::kAccelerometer;
      double before_sq = 0, after_sq = 0;
      int n = 0;
      for (const auto& j : c["provenance"]["records"]) {
        PoseRecord r;
        ASSERT_TRUE(protocol::ParsePoseRecord(j, &r, &error)) << error;
        const auto& triad = accel ? r.acc : r.mag;
        ASSERT_TRUE(triad);
        before_sq += (triad->mean - model->Predict(model->nominal(), r.pose)).squaredNorm();
        after_sq += (triad->mean - model->Predict(theta, r.pose)).squaredNorm();
        ++n;
      }
      ASSERT_EQ(n, static_cast<int>(c["provenance"]["poses"].size()));
      ASSERT_GE(n, 13);
      const double before_rms = std::sqrt(before_sq / (3 * n));
      const double after_rms = std::sqrt(after_sq / (3 * n));
      // The "all" row of the RMS table.
      const std::size_t table = html.find("id=\"rms-" + model_name + "\"");
      ASSERT_NE(table, std::string::npos);
      const std::size_t all = html.find("data-axis=\"all\"", table);
      std::smatch m;
      const std::string row = html.substr(all, html.find("</tr>", all) - all);
      ASSERT_TRUE(std::regex_search(
          row, m,
          std::regex("rms-before\" data-value=\"([^\"]+)\".*rms-after\" data-value=\"([^\"]+)\"")))
          << row;
      EXPECT_NEAR(std::stod(m[1].str()), before_rms, 1e-12 * before_rms);
      EXPECT_NEAR(std::stod(m[2].str()), after_rms, 1e-12 * after_rms);
      std::printf("%s: residual RMS %.4g before, %.4g after (triad unit): factor %.0f\n",
                  model_name.c_str(), before_rms, after_rms, before_rms / after_rms);
      EXPECT_GT(before_rms / after_rms, 10.0) << model_name;
    }
  }
}

// A calibration written before calibrations carried their records still renders: coverage from
// the table angles, and the plots that need measurements say so.
TEST_F(CalibrationReport, WithoutRecordsThePlotsSayWhatIsMissing) {
  std::vector<nlohmann::json> calibrations = Sessions(1)[0].calibrations;
  for (auto& c : calibrations) c["provenance"].erase("records");
  std::string html, error;
  ASSERT_TRUE(report::RenderReportHtml(calibrations, {}, &html, &error)) << error;
  EXPECT_EQ(CheckWellFormed(html), "");
  for (const char* kind : {"residuals-accel13", "convergence-accel13", "coverage-mag13"}) {
    EXPECT_NE(html.find(std::string("id=\"") + kind + "\""), std::string::npos) << kind;
  }
  EXPECT_NE(html.find("carries no pose measurements"), std::string::npos);
  EXPECT_NE(html.find("class=\"pose-directions\""), std::string::npos);
}

// Issue 38: the report opens with the batch's summary, slot by slot (the station's batch.json),
// with this report's unit in bold and each unit's reason; a batch of one without a fixture has
// none.
TEST_F(CalibrationReport, OpensWithTheBatchSummarySlotBySlot) {
  const std::vector<nlohmann::json>& calibrations = Sessions(1)[0].calibrations;
  const std::string device = calibrations[0]["device"];
  report::ReportOptions options;
  options.batch = {{"id", "LOT-117"},
                   {"fixture", "cube4"},
                   {"started", "2026-11-29T04:50:12Z"},
                   {"passed", 1},
                   {"waiting", 0},
                   {"held", 1},
                   {"seconds_to_last_gate", nullptr},
                   {"units",
                    {{{"device", device},
                      {"slot", "1"},
                      {"serial", "6251.00001"},
                      {"state", "passed"},
                      {"poses", 12},
                      {"seconds", 612.4}},
                     {{"device", "imu3"},
                      {"slot", "3"},
                      {"serial", nullptr},
                      {"state", "held"},
                      {"poses", 3},
                      {"seconds", nullptr},
                      {"why", "slot 3 looks rotated 90 deg about its -z"}}}}};
  std::string html, error;
  ASSERT_TRUE(report::RenderReportHtml(calibrations, options, &html, &error)) << error;
  EXPECT_EQ(CheckWellFormed(html), "");
  const std::size_t batch = html.find("<section class=\"batch\"><h2>Batch LOT-117</h2>");
  ASSERT_NE(batch, std::string::npos);
  EXPECT_LT(batch, html.find("<section", html.find("</header>") + 1) + 1);  // the first section
  EXPECT_NE(html.find("Fixture cube4, 2 units, started 2026-11-29T04:50:12Z: 1 passed, 0 "
                      "waiting, 1 held. This report is of " +
                      device),
            std::string::npos);
  EXPECT_NE(html.find("<tr style=\"font-weight:bold\"><td>1</td><td>" + device +
                      "</td><td>6251.00001</td><td class=\"pass\">passed</td><td>12</td>"
                      "<td>612 s</td>"),
            std::string::npos);
  EXPECT_NE(html.find("<td class=\"fail\">held</td><td>3</td><td>&#8212;</td><td>slot 3 looks "
                      "rotated 90 deg about its -z</td>"),
            std::string::npos);
  // A batch of one unit without a fixture: nothing to add.
  options.batch["fixture"] = nullptr;
  options.batch["units"].erase(1);
  ASSERT_TRUE(report::RenderReportHtml(calibrations, options, &html, &error)) << error;
  EXPECT_EQ(html.find("class=\"batch\""), std::string::npos);
}

// Issue 21: a gyroscope's report shows G_w, which source determined which parameter, and the
// angle between the gyro and accelerometer triads.
TEST(GyroReport, SaysWhichSourceDeterminedWhatAndTheTriadAngle) {
  const Session s = RunSession("gyro", drivers::Protocol::kMip, "accel13", "mag13", 9, "gyro12");
  std::string html, error;
  ASSERT_TRUE(report::RenderReportHtml(s.calibrations, {s.dir, "", {}, {}, {}}, &html, &error))
      << error;
  std::filesystem::remove_all(s.dir);
  EXPECT_NE(html.find("G (gyroscope)"), std::string::npos);
  ASSERT_NE(html.find("id=\"sources-gyro12\""), std::string::npos);
  // The scale factors come from the rate segments (and the 25 moves between the 26 static poses,
  // within 3x of the combined sigma: "either (rate segments or moves)"): the static poses alone
  // see the Earth's rate only and leave them hundreds of times less certain; the bias is
  // determined by more than one source.
  const auto row = [&](const std::string& p) {
    const std::size_t at = html.find("id=\"source-gyro12-" + p + "\"");
    return at == std::string::npos ? std::string() : html.substr(at, html.find("</tr>", at) - at);
  };
  EXPECT_NE(html.find("from moves alone (25)"), std::string::npos);
  // The rate segments at two rates: the scale against the rate, linear within the noise (the
  // simulator's gyro is linear; 1 session in 1000 would fail the 0.001 test by chance).
  EXPECT_NE(html.find("id=\"linearity-gyro12\""), std::string::npos);
  EXPECT_NE(html.find("linear within the noise"), std::string::npos);
  for (const char* p : {"Sx", "eps_z"}) {
    const std::string r = row(p);
    const std::size_t verdict = r.rfind("<td>");
    ASSERT_NE(verdict, std::string::npos) << r;
    EXPECT_NE(r.find("rate segments", verdict), std::string::npos) << r;
    EXPECT_EQ(r.find("static poses", verdict), std::string::npos) << r;
  }
  EXPECT_NE(row("bx").find("either"), std::string::npos) << row("bx");
  // The triad angle within 4 sigma of the truth's.
  std::smatch m;
  ASSERT_TRUE(std::regex_search(
      html, m, std::regex("id=\"triad-angle\" data-value=\"([^\"]+)\".*?&#177; ([0-9.]+)&#176;")));
  const double angle = std::stod(m[1].str()), sigma = std::stod(m[2].str()) * M_PI / 180;
  std::string e;
  auto acc = MakeModel("accel13", ModelContext{}, &e);
  auto gyro = MakeModel("gyro12", ModelContext{}, &e);
  const Eigen::Vector3d ea = s.accel_truth.segment<3>(acc->index_of("eps_x"));
  const Eigen::Vector3d eg = s.gyro_truth.segment<3>(gyro->index_of("eps_x"));
  const Mat3<double> R = C_eps(eg.x(), eg.y(), eg.z()) * C_eps(ea.x(), ea.y(), ea.z()).transpose();
  const double truth = std::acos(std::clamp((R.trace() - 1) / 2, -1.0, 1.0));
  EXPECT_GT(sigma, 0.0);
  EXPECT_LT(std::abs(angle - truth), 4 * sigma) << angle << " truth " << truth;
}

// A table without a rate mode: 26 static poses and the 25 moves between them. The report's
// sources table has the static poses and the moves, and says the moves determined the scale
// factors and the misalignment.
TEST(GyroReport, MovesAloneSayWhatTheyDetermine) {
  const Session s =
      RunSession("gyro_moves", drivers::Protocol::kXbus, "accel13", "mag13", 11, "gyro12", false);
  std::string html, error;
  ASSERT_TRUE(report::RenderReportHtml(s.calibrations, {s.dir, "", {}, {}, {}}, &html, &error))
      << error;
  std::filesystem::remove_all(s.dir);
  EXPECT_NE(html.find("from static poses alone (26)"), std::string::npos);
  EXPECT_NE(html.find("from moves alone (25)"), std::string::npos);
  EXPECT_EQ(html.find("from rate segments alone"), std::string::npos);
  EXPECT_EQ(html.find("id=\"linearity-gyro12\""), std::string::npos);  // no rate segment
  const auto row = [&](const std::string& p) {
    const std::size_t at = html.find("id=\"source-gyro12-" + p + "\"");
    return at == std::string::npos ? std::string() : html.substr(at, html.find("</tr>", at) - at);
  };
  for (const char* p : {"Sx", "Sy", "Sz", "alpha1", "eps_z"}) {
    EXPECT_NE(row(p).find("<td>moves</td>"), std::string::npos) << row(p);
  }
}

TEST_F(CalibrationReport, MalformedInputGivesAnErrorNotACrash) {
  const nlohmann::json good = Sessions(1)[0].calibrations[0];
  std::string html = "untouched", error;
  auto refused = [&](const std::vector<nlohmann::json>& docs, const std::string& words) {
    error.clear();
    EXPECT_FALSE(report::RenderReportHtml(docs, {}, &html, &error)) << words;
    EXPECT_NE(error.find(words), std::string::npos) << "error: " << error;
    EXPECT_EQ(html, "untouched");
  };
  refused({}, "no calibration");
  refused({nlohmann::json::array()}, "JSON object");
  refused({nlohmann::json{{"model", "accel13"}}}, "'device'");
  nlohmann::json bad = good;
  bad["model"] = "accel99";
  refused({bad}, "unknown");
  bad = good;
  bad["params"].erase("Sy");
  refused({bad}, "'Sy'");
  bad = good;
  bad["params"]["bx"]["value"] = "12";
  refused({bad}, "'bx'");
  bad = good;
  bad["covariance"].erase(0);
  refused({bad}, "covariance");
  bad = good;
  bad["provenance"]["records"][3]["acc"]["mean"] = {1, 2};
  refused({bad}, "provenance.records[3]");
  bad = good;
  bad["parameter_order"][0] = "Sz";
  refused({bad}, "parameter_order");
  bad = good;
  bad["gate"] = "passed";
  refused({bad}, "gate");
  bad = good;
  bad["device"] = "other";
  refused({good, bad}, "two devices");
  refused({good, good}, "two calibrations");
  bad = good;
  bad["context"]["mounting"] = {{1, 0, 0}, {0, 1, 0}, {0, 0, -1}};
  refused({bad}, "mounting");

  // Every key removed, or replaced by a value of the wrong type: an error or a report, never a
  // crash.
  int refusals = 0, rendered = 0;
  for (const auto& [key, value] : good.items()) {
    for (const nlohmann::json& replacement :
         {nlohmann::json(), nlohmann::json("x"), nlohmann::json(-1), nlohmann::json::array(),
          nlohmann::json::object()}) {
      nlohmann::json mutated = good;
      if (replacement.is_null()) {
        mutated.erase(key);
      } else {
        mutated[key] = replacement;
      }
      std::string out;
      (report::RenderReportHtml({mutated}, {}, &out, &error) ? rendered : refusals)++;
    }
  }
  std::printf("mutated calibrations: %d refused, %d rendered\n", refusals, rendered);
  EXPECT_GT(refusals, 0);
}

}  // namespace
}  // namespace turncal
