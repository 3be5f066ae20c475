// The calibration certificate (report/certificate.h) on a calibration the station wrote for a
// simulated session (tests/report/certificate_accel13.json: `turncal sim --protocol mip --seed 4`
// replayed by `turncald --replay --once --state-dir`, its records and covariance rounded to six
// digits to keep the file small): the hash verifies and any edit fails it, the rendering is
// deterministic, U is 2 sigma, the gate's check is u <= tolerance, and a parameter without a
// sigma says "not determined".

#include "report/certificate.h"

#include <gtest/gtest.h>

#include <fstream>
#include <regex>
#include <sstream>

namespace turncal::report {
namespace {

nlohmann::json Fixture(const std::string& name = "certificate_accel13.json") {
  std::ifstream in(std::string(TURNCAL_SOURCE_DIR) + "/tests/report/" + name);
  std::stringstream text;
  text << in.rdbuf();
  return nlohmann::json::parse(text.str());
}

std::string Render(const CertificateSource& source, std::string* hash = nullptr) {
  std::string html, h, error;
  EXPECT_TRUE(RenderCertificateHtml(source, &html, &h, &error)) << error;
  if (hash) *hash = h;
  return html;
}

CertificateSource Source() {
  CertificateSource s;
  s.calibration = Fixture();
  s.station = "lab-2";
  s.source = "state directory /var/lib/turncal";
  return s;
}

// The embedded data block.
nlohmann::json DataBlock(const std::string& html) {
  const std::string open = "<script type=\"application/json\" id=\"turncal-certificate-data\">";
  const std::size_t from = html.find(open);
  const std::size_t to = html.find("</script>", from);
  EXPECT_NE(from, std::string::npos);
  return nlohmann::json::parse(html.substr(from + open.size(), to - from - open.size()));
}

const nlohmann::json& Parameter(const nlohmann::json& data, const std::string& name) {
  for (const auto& p : data["parameters"]) {
    if (p["name"] == name) return p;
  }
  ADD_FAILURE() << "no parameter " << name;
  return data;
}

// The <tr id="param-NAME"> row of the parameter table.
std::string Row(const std::string& html, const std::string& name) {
  const std::size_t from = html.find("<tr id=\"param-" + name + "\"");
  EXPECT_NE(from, std::string::npos) << name;
  return html.substr(from, html.find("</tr>", from) - from);
}

TEST(Certificate, HashVerifiesAndIsShownInTheMetaAndTheFooter) {
  std::string hash;
  const std::string html = Render(Source(), &hash);
  const CertificateCheck check = VerifyCertificateHtml(html);
  EXPECT_TRUE(check.ok) << check.reason;
  EXPECT_EQ(check.hash_claimed, hash);
  EXPECT_EQ(check.hash_computed, hash);
  EXPECT_NE(html.find("<meta name=\"turncal-certificate-sha256\" content=\"" + hash + "\">"),
            std::string::npos);
  EXPECT_NE(html.find("Content hash (SHA-256): <span class=\"hash\" id=\"content-hash\">" + hash),
            std::string::npos);
  EXPECT_NE(html.find("<h1>Calibration certificate</h1>"), std::string::npos);
  EXPECT_NE(html.find("lab-2-imu-accel13-v3"), std::string::npos);
  // Nothing fetched, nothing run: no external resource and no script but the data block.
  EXPECT_EQ(html.find("http"), std::string::npos);
  EXPECT_EQ(html.find("<script>"), std::string::npos);
  EXPECT_FALSE(std::regex_search(html, std::regex("\\b(nan|inf)\\b", std::regex::icase)));
}

// A unit with history (issue 39 item 3): `turncal registry drift --json`'s rows of the
// certificate's model become a drift table in the report units and a summary in the data block;
// another model's rows and each row's history are left out; the page still verifies.
TEST(Certificate, AUnitsDriftIsShownInItsUnitsAndKeptInTheDataBlock) {
  CertificateSource source = Source();
  const nlohmann::json history = nlohmann::json::array({{{"t", "2026-01-01"}, {"value", 1e-3}}});
  source.drift = nlohmann::json::array(
      {{{"model", "accel13"},
        {"parameter", "Sx"},
        {"calibrations", 12},
        {"history", history},
        {"first", "2026-01-01"},
        {"last", "2026-11-01"},
        {"repeatability", {{"value", 20e-6}, {"ci95", {10e-6, 60e-6}}}},
        {"trend", {{"per_month", 5e-6}, {"sigma_per_month", 1e-6}, {"resolved", true}}},
        {"tolerance", 100e-6},
        {"recalibrate",
         {{"date", "2027-06-30"}, {"sigma_days", 40.0}, {"not_before", "2027-04-01"}}}},
       {{"model", "mag13"}, {"parameter", "bx"}, {"calibrations", 3}, {"history", history}}});
  std::string hash;
  const std::string html = Render(source, &hash);
  EXPECT_TRUE(VerifyCertificateHtml(html).ok);
  const std::size_t at = html.find("<tr id=\"drift-accel13-Sx\">");
  ASSERT_NE(at, std::string::npos);
  const std::string row = html.substr(at, html.find("</tr>", at) - at);
  // ppm, as the parameter table shows Sx: 20 [10, 60], +5 +- 1 a month, tolerance 100.
  EXPECT_NE(row.find("20 [10, 60]"), std::string::npos) << row;
  EXPECT_NE(row.find("+5 &#177; 1"), std::string::npos) << row;
  EXPECT_NE(row.find("2027-06-30 &#177; 40 d"), std::string::npos) << row;
  EXPECT_NE(row.find("2027-04-01"), std::string::npos) << row;
  EXPECT_NE(row.find("ppm"), std::string::npos) << row;
  EXPECT_EQ(html.find("drift-mag13"), std::string::npos);
  const nlohmann::json data = DataBlock(html);
  ASSERT_EQ(data["drift"].size(), 1u);
  EXPECT_FALSE(data["drift"][0].contains("history"));
  // Without a trend anywhere (one calibration), no section.
  source.drift = nlohmann::json::array({{{"model", "accel13"}, {"parameter", "Sx"}}});
  EXPECT_EQ(Render(source, &hash).find("Drift over the unit"), std::string::npos);
}

TEST(Certificate, TheSameCalibrationGivesTheSameBytes) {
  std::string a_hash, b_hash;
  const std::string a = Render(Source(), &a_hash);
  const std::string b = Render(Source(), &b_hash);
  EXPECT_EQ(a, b);
  EXPECT_EQ(a_hash, b_hash);
  CertificateSource other = Source();
  other.station = "lab-3";
  EXPECT_NE(Render(other), a);
}

TEST(Certificate, FlippingOneDigitOfAParameterValueFailsVerification) {
  std::string html = Render(Source());
  const std::string row = Row(html, "bx");
  // The value cell is the third <td>: change its first digit.
  std::size_t at = html.find(row);
  for (int cells = 0; cells < 3; ++cells) at = html.find("<td", at + 1);
  at = html.find_first_of("0123456789", at + 4);
  html[at] = html[at] == '9' ? '8' : static_cast<char>(html[at] + 1);
  const CertificateCheck check = VerifyCertificateHtml(html);
  EXPECT_FALSE(check.ok);
  EXPECT_FALSE(check.not_a_certificate);
  EXPECT_NE(check.hash_claimed, check.hash_computed);
  EXPECT_NE(check.reason.find("changed"), std::string::npos) << check.reason;
}

TEST(Certificate, AnyByteChangedFailsWhitespaceToo) {
  const std::string html = Render(Source());
  EXPECT_FALSE(VerifyCertificateHtml(html + "\n").ok);
  std::string crlf;
  for (char ch : html) crlf += ch == '\n' ? std::string("\r\n") : std::string(1, ch);
  EXPECT_FALSE(VerifyCertificateHtml(crlf).ok);
  std::string data = html;
  const std::size_t at = data.find("\"station\": \"lab-2\"");
  ASSERT_NE(at, std::string::npos);
  data.replace(at, 18, "\"station\": \"lab-9\"");  // the data block only
  EXPECT_FALSE(VerifyCertificateHtml(data).ok);
}

TEST(Certificate, EditingTheHashItselfFailsVerification) {
  std::string hash;
  const std::string html = Render(Source(), &hash);
  const std::string forged(64, hash[0] == 'a' ? 'b' : 'a');
  // The <meta> only: the visible hash no longer agrees.
  std::string meta_only = html;
  meta_only.replace(meta_only.find(hash), 64, forged);
  CertificateCheck check = VerifyCertificateHtml(meta_only);
  EXPECT_FALSE(check.ok);
  EXPECT_NE(check.reason.find("visible"), std::string::npos) << check.reason;
  // Both: they agree with each other, not with the content.
  std::string both = std::regex_replace(html, std::regex(hash), forged);
  check = VerifyCertificateHtml(both);
  EXPECT_FALSE(check.ok);
  EXPECT_EQ(check.hash_claimed, forged);
  EXPECT_EQ(check.hash_computed, hash);  // the file is otherwise unchanged
  // A hash that is not one.
  std::string short_hash = html;
  short_hash.replace(short_hash.find(hash), 64, "123");
  EXPECT_FALSE(VerifyCertificateHtml(short_hash).ok);
}

TEST(Certificate, SomethingElseIsNotACertificate) {
  const CertificateCheck check = VerifyCertificateHtml("<!DOCTYPE html><html></html>");
  EXPECT_FALSE(check.ok);
  EXPECT_TRUE(check.not_a_certificate);
}

TEST(Certificate, ExpandedUncertaintyIsTwiceTheStandardUncertainty) {
  const CertificateSource source = Source();
  const nlohmann::json data = DataBlock(Render(source));
  EXPECT_EQ(data["coverage_factor"], 2.0);
  ASSERT_EQ(data["parameters"].size(), 13u);
  for (const auto& p : data["parameters"]) {
    const std::string name = p["name"];
    const double sigma = source.calibration["params"][name]["sigma"];
    EXPECT_EQ(p["u"].get<double>(), sigma) << name;
    EXPECT_EQ(p["U"].get<double>(), 2 * sigma) << name;
    EXPECT_EQ(p["value"].get<double>(), source.calibration["params"][name]["value"].get<double>());
  }
  // bz's U on the page: mg, two significant digits (sigma 1.69e-4 m/s^2 = 0.01726 mg).
  EXPECT_NE(Row(Render(source), "bz").find("<td>0.035&#8201;mg</td>"), std::string::npos)
      << Row(Render(source), "bz");
}

TEST(Certificate, TheGateCheckIsTheStandardUncertaintyAgainstTheTolerance) {
  CertificateSource source = Source();
  const double sigma = source.calibration["params"]["Sx"]["sigma"];
  // u <= T < U: within (the gate judges u, not U).
  source.calibration["tolerances"]["Sx"] = 1.5 * sigma;
  nlohmann::json data = DataBlock(Render(source));
  EXPECT_EQ(Parameter(data, "Sx")["check"], "within");
  EXPECT_EQ(Parameter(data, "Sx")["tolerance_u"], 1.5 * sigma);
  source.calibration["tolerances"]["Sx"] = 0.5 * sigma;
  const std::string html = Render(source);
  data = DataBlock(html);
  EXPECT_EQ(Parameter(data, "Sx")["check"], "exceeds");
  EXPECT_NE(Row(html, "Sx").find("class=\"exceeds\""), std::string::npos);
  // Installation parameters are not gated.
  EXPECT_EQ(Parameter(data, "beta")["check"], "not gated");
  EXPECT_TRUE(Parameter(data, "beta")["tolerance_u"].is_null());
}

TEST(Certificate, ParameterWithoutSigmaSaysNotDetermined) {
  CertificateSource source = Source();
  source.calibration["params"]["beta"]["sigma"] = nullptr;
  source.calibration["params"]["bz"]["sigma"] = nullptr;
  const std::string html = Render(source);
  EXPECT_TRUE(VerifyCertificateHtml(html).ok);
  EXPECT_NE(Row(html, "beta").find("not determined"), std::string::npos);
  EXPECT_NE(Row(html, "bz").find("not determined"), std::string::npos);
  EXPECT_FALSE(std::regex_search(html, std::regex("\\b(nan|inf)\\b", std::regex::icase)));
  const nlohmann::json data = DataBlock(html);
  EXPECT_TRUE(Parameter(data, "beta")["u"].is_null());
  EXPECT_TRUE(Parameter(data, "beta")["U"].is_null());
  EXPECT_EQ(Parameter(data, "bz")["check"], "not determined");
}

TEST(Certificate, IdentityFromTheDeviceAndFromTheCaller) {
  CertificateSource source = Source();
  std::string html = Render(source);
  EXPECT_NE(html.find("not reported by the device"), std::string::npos);  // a replay has none
  source.calibration["provenance"]["device_identity"] = {
      {"protocol", "mip"},      {"model_name", "3DM-GX5-25"}, {"model_number", "6251-4220"},
      {"serial", "6251.81234"}, {"firmware", "1.1.71"},       {"rate_hz", 500}};
  source.identity = {{"firmware", "1.1.72"}};
  html = Render(source);
  EXPECT_EQ(html.find("not reported by the device"), std::string::npos);
  EXPECT_NE(html.find("6251.81234"), std::string::npos);
  EXPECT_NE(html.find("3DM-GX5-25 (6251-4220)"), std::string::npos);
  EXPECT_NE(html.find("1.1.72"), std::string::npos);  // the caller's wins
  const nlohmann::json data = DataBlock(html);
  EXPECT_EQ(data["device"]["serial"], "6251.81234");
  EXPECT_TRUE(data["device"]["reported_by_device"].get<bool>());
}

TEST(Certificate, ContentHoldsTheEnvironmentProcedureAndVerdict) {
  const nlohmann::json data = DataBlock(Render(Source()));
  EXPECT_NEAR(data["environment"]["gravity_mps2"].get<double>(), 9.77821, 1e-5);
  EXPECT_EQ(data["procedure"]["poses"]["static_poses"], 36);
  EXPECT_EQ(data["procedure"]["records"], 36);
  EXPECT_NEAR(data["procedure"]["dwell_s_median"].get<double>(), 3.0, 0.1);
  EXPECT_EQ(data["verdict"]["text"], "PASS");
  EXPECT_EQ(data["calibration"]["version"], 3);
  EXPECT_EQ(data["calibration"]["time_utc"], "2026-03-14T09:26:53Z");
}

// A session sped up 20x (or replayed) runs the host's clock at another pace: where every record
// has the device's own window, the dwell and the session's length are the device's.
TEST(Certificate, DwellAndSessionLengthAreTheDevicesClockWhereEveryRecordHasIt) {
  CertificateSource source = Source();
  nlohmann::json& records = source.calibration["provenance"]["records"];
  ASSERT_TRUE(records.is_array());
  ASSERT_FALSE(records.empty());
  for (std::size_t i = 0; i < records.size(); ++i) {
    nlohmann::json& r = records[i];
    const double host0 = r["t_start"].get<double>(), host1 = r["t_end"].get<double>();
    r["t_sensor_start"] = 1000.0 + 20.0 * host0;  // the host ran 20x faster than the device
    r["t_sensor_end"] = 1000.0 + 20.0 * host1;
  }
  nlohmann::json data = DataBlock(Render(source));
  EXPECT_EQ(data["procedure"]["clock"], "sensor");
  EXPECT_NEAR(data["procedure"]["dwell_s_median"].get<double>(), 60.0, 2.0);
  EXPECT_NE(Render(source).find("(the device's clock)"), std::string::npos);
  records[0].erase("t_sensor_start");  // one record without: the host's clock for all
  data = DataBlock(Render(source));
  EXPECT_EQ(data["procedure"]["clock"], "host");
  EXPECT_NEAR(data["procedure"]["dwell_s_median"].get<double>(), 3.0, 0.1);
}

TEST(Certificate, MalformedCalibrationIsRefusedWithAMessage) {
  CertificateSource source = Source();
  source.calibration.erase("params");
  std::string html = "untouched", hash, error;
  EXPECT_FALSE(RenderCertificateHtml(source, &html, &hash, &error));
  EXPECT_EQ(html, "untouched");
  EXPECT_FALSE(error.empty());
  source.calibration = nlohmann::json::array();
  EXPECT_FALSE(RenderCertificateHtml(source, &html, &hash, &error));
}

TEST(Certificate, NumberNamesStationDeviceModelAndVersion) {
  EXPECT_EQ(CertificateNumber("lab 2", "imu1", "mag13", 4), "lab_2-imu1-mag13-v4");
  EXPECT_EQ(CertificateNumber("", "imu", "accel13", 1), "unknown-imu-accel13-v1");
}

TEST(Certificate, Sha256OfKnownInput) {
  EXPECT_EQ(Sha256Hex("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
}

// A calibration over temperature (tests/report/certificate_mag13T.json: mag13@T as turncald wrote
// it in tests/daemon/e2e_thermal_test.py's session, an industrial MIP IMU at 0, 20 and 40 degC; its
// provenance kept to every 8th record, rounded to six digits): the range, U = 2u at the range's
// ends and at T0 as the document states sigma there, the coefficients, the gate's check on the
// largest u over the range.
CertificateSource ThermalSource() {
  CertificateSource s;
  s.calibration = Fixture("certificate_mag13T.json");
  s.station = "lab-2";
  return s;
}

TEST(Certificate, OverTemperatureStatesTheRangeTheCoefficientsAndUAtTheEndsAndT0) {
  const CertificateSource source = ThermalSource();
  std::string hash;
  const std::string html = Render(source, &hash);
  EXPECT_TRUE(VerifyCertificateHtml(html).ok);
  EXPECT_NE(html.find("Results over temperature"), std::string::npos);
  EXPECT_NE(html.find("0.0 &#8230; 40.0 &#176;C"), std::string::npos);
  const nlohmann::json data = DataBlock(html);
  const nlohmann::json& doc = source.calibration["temperature"];
  EXPECT_EQ(data["calibration"]["model"], "mag13@T");
  EXPECT_DOUBLE_EQ(data["temperature"]["t_min_c"].get<double>(), doc["t_min_c"].get<double>());
  EXPECT_DOUBLE_EQ(data["temperature"]["t_max_c"].get<double>(), doc["t_max_c"].get<double>());
  EXPECT_DOUBLE_EQ(data["temperature"]["t0_c"].get<double>(), doc["t0_c"].get<double>());
  EXPECT_EQ(data["parameters"].size(), 13u);
  for (const auto& [name, at_t0] : doc["at"]["t0"].items()) {
    const nlohmann::json& p = Parameter(data, name);
    EXPECT_EQ(p["order"], doc["orders"][name]) << name;
    for (const auto& [key, where] :
         {std::pair{"t_min", p["t_min"]}, std::pair{"t0", p}, std::pair{"t_max", p["t_max"]}}) {
      const nlohmann::json& stated = doc["at"][key][name];
      EXPECT_NEAR(where["value"].get<double>(), stated["value"].get<double>(),
                  1e-9 * (1 + std::abs(stated["value"].get<double>())))
          << name << " at " << key;
      EXPECT_NEAR(where["u"].get<double>(), stated["sigma"].get<double>(),
                  1e-9 * stated["sigma"].get<double>())
          << name << " at " << key;
      EXPECT_DOUBLE_EQ(where["U"].get<double>(), 2 * where["u"].get<double>()) << name;
    }
    // The largest u over the range is at least u at either end and at T0.
    EXPECT_GE(p["u_worst"].get<double>() * (1 + 1e-12),
              std::max({p["u"].get<double>(), p["t_min"]["u"].get<double>(),
                        p["t_max"]["u"].get<double>()}))
        << name;
  }
  const nlohmann::json& coefficients = data["temperature"]["coefficients"];
  EXPECT_EQ(coefficients.size(), doc["coefficient_order"].size());
  for (const auto& k : coefficients) {
    const nlohmann::json& stated = doc["coefficients"][k["name"].get<std::string>()];
    EXPECT_DOUBLE_EQ(k["value"].get<double>(), stated["value"].get<double>());
    EXPECT_DOUBLE_EQ(k["U"].get<double>(), 2 * stated["sigma"].get<double>());
  }
  const nlohmann::json* bx_dt = nullptr;
  for (const auto& k : coefficients) {
    if (k["name"] == "bx*dT") bx_dt = &k;
  }
  ASSERT_NE(bx_dt, nullptr);
  EXPECT_EQ((*bx_dt)["unit"], "field/degC");  // the device unit of the field, per degC
  EXPECT_EQ((*bx_dt)["power"], 1);
  EXPECT_NE(html.find("mG/&#176;C"), std::string::npos);
  EXPECT_EQ(data["verdict"]["pass"], true);
  EXPECT_EQ(data["fit"]["parameters"], doc["coefficient_order"].size());
}

TEST(Certificate, OverTemperatureTheGateCheckIsTheLargestUOverTheRange) {
  CertificateSource source = ThermalSource();
  const nlohmann::json data = DataBlock(Render(source));
  // The parameter whose u grows most away from T0; a tolerance between u at T0 and its largest u.
  std::string name;
  double ratio = 0;
  for (const auto& p : data["parameters"]) {
    if (p["tolerance_u"].is_null()) continue;
    const double r = p["u_worst"].get<double>() / p["u"].get<double>();
    if (r > ratio) ratio = r, name = p["name"];
  }
  ASSERT_GT(ratio, 1.05) << name;
  const nlohmann::json& p = Parameter(data, name);
  source.calibration["tolerances"][name] =
      0.5 * (p["u"].get<double>() + p["u_worst"].get<double>());
  const std::string html = Render(source);
  EXPECT_EQ(Parameter(DataBlock(html), name)["check"], "exceeds");
  EXPECT_NE(Row(html, name).find("&gt; T &#10007;"), std::string::npos) << Row(html, name);
  source.calibration["tolerances"][name] = 1.01 * p["u_worst"].get<double>();
  EXPECT_EQ(Parameter(DataBlock(Render(source)), name)["check"], "within");
}

TEST(Certificate, OverTemperatureWithoutTheCovarianceStatesUAtT0Only) {
  CertificateSource source = ThermalSource();
  source.calibration["temperature"].erase("covariance");
  const std::string html = Render(source);
  const nlohmann::json data = DataBlock(html);
  const nlohmann::json& g11 = Parameter(data, "g11");
  EXPECT_DOUBLE_EQ(g11["u"].get<double>(),
                   source.calibration["temperature"]["coefficients"]["g11"]["sigma"].get<double>());
  EXPECT_TRUE(g11["t_min"]["u"].is_null());
  EXPECT_TRUE(g11["u_worst"].is_null());
  EXPECT_EQ(g11["check"], "not determined");
  EXPECT_NE(html.find("u is stated at T0 only"), std::string::npos);
}

TEST(Certificate, OverTemperatureMalformedIsRefusedWithTheReason) {
  CertificateSource source = ThermalSource();
  source.calibration.erase("temperature");
  std::string html, hash, error;
  EXPECT_FALSE(RenderCertificateHtml(source, &html, &hash, &error));
  EXPECT_NE(error.find("no \"temperature\" section"), std::string::npos) << error;
  source = ThermalSource();
  source.calibration["base_model"] = "accel99";
  EXPECT_FALSE(RenderCertificateHtml(source, &html, &hash, &error));
  EXPECT_NE(error.find("accel99"), std::string::npos) << error;
}

}  // namespace
}  // namespace turncal::report
