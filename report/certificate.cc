// The certificate page (report/certificate.h): CertificateContent's JSON laid out on one or two
// A4 pages. Every number shown comes from the content, so the page and its data block agree.

#include "report/certificate.h"
#include "report/drift_section.h"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <vector>

#include "report/svg.h"

namespace turncal::report {
namespace {

using Json = nlohmann::json;
using svg::Escape;

// Print first: A4 with the margins a certificate binder leaves; on screen the same sheet on grey.
// System fonts only (nothing is fetched).
constexpr const char* kCertStyle = R"(
@page { size: A4; margin: 12mm 14mm 12mm 16mm; }
* { box-sizing: border-box; }
html { background: #e8e8e8; }
body { margin: 0; color: #1a1a1a; font: 9pt/1.3 "DejaVu Sans", "Helvetica Neue", Arial, sans-serif; }
.sheet { width: 210mm; min-height: 297mm; margin: 8mm auto; padding: 12mm 14mm 12mm 16mm; background: #fff; box-shadow: 0 1px 6px rgba(0,0,0,.25); }
@media print { html { background: none; } .sheet { width: auto; min-height: 0; margin: 0; padding: 0; box-shadow: none; } }
header { display: grid; grid-template-columns: 1fr auto; gap: 1mm 8mm; border-bottom: 2.2pt solid #1f3b5c; padding-bottom: 2mm; }
.issuer { grid-column: 1 / 3; font-size: 8pt; letter-spacing: .08em; text-transform: uppercase; color: #1f3b5c; }
h1 { margin: 0; font-size: 20pt; font-weight: 600; color: #1f3b5c; }
.number { text-align: right; font-size: 8.5pt; color: #444; }
.number strong { display: block; font-size: 10.5pt; color: #1a1a1a; font-family: "DejaVu Sans Mono", monospace; }
.badge { display: inline-block; margin-top: 1.5mm; padding: .6mm 3mm; border: 1.2pt solid; border-radius: 1mm; font-weight: 700; letter-spacing: .05em; }
.badge.pass { color: #17622a; border-color: #17622a; } .badge.fail { color: #a01010; border-color: #a01010; }
h2 { font-size: 10pt; color: #1f3b5c; margin: 3.5mm 0 1.2mm; padding-bottom: .6mm; border-bottom: .6pt solid #b8c4d2; break-after: avoid; }
.facts { display: grid; grid-template-columns: 1fr 1fr; gap: 0 8mm; }
.facts section { break-inside: avoid; }
table { border-collapse: collapse; width: 100%; }
table.kv th { width: 27%; text-align: left; font-weight: normal; color: #555; vertical-align: top; padding: .3mm 2mm .3mm 0; white-space: nowrap; }
table.kv td { padding: .3mm 0; vertical-align: top; }
.missing-info { color: #777; font-style: italic; }
table.params { font-size: 8.8pt; margin-top: 1mm; }
table.params th { text-align: right; font-weight: 600; padding: 1mm 1.6mm; border-bottom: .9pt solid #1f3b5c; background: #eef2f6; white-space: nowrap; }
table.params th:first-child, table.params td:first-child, table.params th.left { text-align: left; }
table.params td { text-align: right; padding: .45mm 1.6mm; border-bottom: .4pt solid #dde3ea; white-space: nowrap; font-variant-numeric: tabular-nums; }
table.params tr { break-inside: avoid; }
table.params td.name { font-family: "DejaVu Sans Mono", monospace; }
table.params td.kind { text-align: left; color: #555; }
table.params td.nd { text-align: center; color: #777; font-style: italic; }
table.params td.check { text-align: left; }
table.params.thermal { font-size: 7.6pt; }
table.params.thermal th, table.params.thermal td { padding-left: 1mm; padding-right: 1mm; }
table.params.thermal th { white-space: normal; vertical-align: bottom; }
tr.within td.check { color: #17622a; } tr.exceeds td { background: #fbe9e9; } tr.exceeds td.check { color: #a01010; font-weight: 600; }
tr.ungated td.check, tr.undetermined td.check { color: #666; }
.statement { font-size: 7.8pt; color: #333; margin: 1.5mm 0 0; text-align: justify; }
ul { margin: .5mm 0 1mm; padding-left: 5mm; } li { margin: .2mm 0; }
.verdict-line { font-size: 10pt; margin: 1mm 0; } .verdict-line strong.pass { color: #17622a; } .verdict-line strong.fail { color: #a01010; }
.notes { font-size: 7.8pt; color: #444; } section.verdict p { margin: .8mm 0; }
footer { margin-top: 4mm; padding-top: 1.5mm; border-top: .6pt solid #b8c4d2; font-size: 8pt; color: #333; break-inside: avoid; }
footer .hash { font-family: "DejaVu Sans Mono", monospace; font-size: 8.5pt; font-weight: 600; word-break: break-all; color: #1a1a1a; }
footer p { margin: .6mm 0; }
)";

// "-0" and "-0.00" as "0": a value rounded to zero has no sign.
std::string CertUnsigned(std::string s) {
  if (!s.empty() && s[0] == '-' && s.find_first_not_of("-0.") == std::string::npos) s.erase(0, 1);
  return s;
}

// Decimals that give `v` two significant digits (the GUM's advice for an uncertainty).
int CertDecimalsFor(double v) {
  if (!(v > 0) || !std::isfinite(v)) return 6;
  const int exponent = static_cast<int>(std::floor(std::log10(v)));
  return std::clamp(1 - exponent, 0, 15);
}

std::string CertFixed(double v, int decimals) {
  return CertUnsigned(fmt::format("{:.{}f}", v, decimals));
}

// A unit as printed: degrees with the degree sign.
std::string CertUnit(const std::string& unit) {
  if (unit == "deg") return "&#176;";
  if (unit == "deg/h") return "&#176;/h";
  if (unit == "deg/h/g") return "&#176;/h/g";
  return unit.empty() ? "" : "&#8201;" + Escape(unit);
}

std::string CertWithUnit(const std::string& number, const std::string& unit) {
  return number + CertUnit(unit);
}

double CertNum(const Json& j, const char* key) {
  const auto it = j.find(key);
  return it != j.end() && it->is_number() ? it->get<double>() : NAN;
}

std::string CertText(const Json& j, const char* key) {
  const auto it = j.find(key);
  return it != j.end() && it->is_string() ? it->get<std::string>() : "";
}

std::string CertRow(const std::string& label, const std::string& value_html) {
  return "<tr><th>" + label + "</th><td>" + value_html + "</td></tr>";
}

// A value of the identity, or a plain statement that the device did not report it.
std::string CertIdentityValue(const Json& device, const char* key) {
  const std::string v = CertText(device, key);
  if (!v.empty()) return Escape(v);
  return R"(<span class="missing-info">not reported by the device</span>)";
}

std::string CertList(const Json& items, const char* css_class) {
  if (!items.is_array() || items.empty()) return "";
  std::string o = fmt::format("<ul class=\"{}\">", css_class);
  for (const Json& s : items)
    o += "<li>" + Escape(s.is_string() ? s.get<std::string>() : s.dump()) + "</li>";
  return o + "</ul>";
}

std::string CertHeader(const Json& c) {
  const bool pass = c["verdict"].value("pass", false);
  return fmt::format(
      R"(<header><div class="issuer">turncal &#183; IMU calibration &#183; station {}</div>)"
      R"(<h1>Calibration certificate</h1><div class="number">Certificate No.<strong>{}</strong>)"
      R"(<span class="badge {}">{}</span></div></header>)",
      Escape(c.value("station", "")), Escape(c.value("number", "")), pass ? "pass" : "fail",
      pass ? "PASS" : "NOT PASSED");
}

std::string CertInstrument(const Json& c) {
  const Json& d = c["device"];
  const Json& cal = c["calibration"];
  std::string o = "<section><h2>Instrument</h2><table class=\"kv\">";
  o += CertRow("Serial number", CertIdentityValue(d, "serial"));
  o += CertRow("Device model", CertIdentityValue(d, "model_name"));
  o += CertRow("Firmware", CertIdentityValue(d, "firmware"));
  std::string link = Escape(CertText(d, "protocol"));
  if (const double rate = CertNum(d, "rate_hz"); std::isfinite(rate)) {
    link += fmt::format("{}{:g} Hz", link.empty() ? "" : ", ", rate);
  }
  if (!link.empty()) o += CertRow("Interface", link);
  o += CertRow("Sensor", Escape(CertText(cal, "sensor")) + " (<code>" +
                             Escape(CertText(cal, "model")) + "</code>), as <code>" +
                             Escape(CertText(d, "name")) + "</code>");
  return o + "</table></section>";
}

std::string CertCalibration(const Json& c) {
  const Json& cal = c["calibration"];
  std::string o = "<section><h2>Calibration</h2><table class=\"kv\">";
  o += CertRow("Station", Escape(c.value("station", "")));
  o += CertRow("Date (UTC)", Escape(CertText(cal, "time_utc")));
  o += CertRow("Version", fmt::format("{}", cal.value("version", 0)));
  o += CertRow("Software", "turncal " + Escape(CertText(cal, "software")));
  if (const std::string s = c.value("source", ""); !s.empty()) o += CertRow("Read from", Escape(s));
  if (const std::string s = c.value("issued_utc", ""); !s.empty()) {
    o += CertRow("Certificate issued", Escape(s));
  }
  return o + "</table></section>";
}

std::string CertEnvironment(const Json& c) {
  const Json& e = c["environment"];
  std::string o = "<section><h2>Environment (reference values)</h2><table class=\"kv\">";
  std::string g = fmt::format("{:.5f} m/s&#178;", CertNum(e, "gravity_mps2"));
  if (e.contains("g_ned_mps2")) {
    const Json& v = e["g_ned_mps2"];
    g += fmt::format(" <span class=\"notes\">(NED {:g}, {:g}, {:g})</span>", v[0].get<double>(),
                     v[1].get<double>(), v[2].get<double>());
  }
  o += CertRow("Local gravity |g|", g);
  if (const double b = CertNum(e, "field_magnitude"); std::isfinite(b)) {
    std::string field = fmt::format("{:.4f} <span class=\"notes\">(device unit)</span>", b);
    if (const double dip = CertNum(e, "field_dip_deg"); std::isfinite(dip)) {
      field += fmt::format(", dip {:.2f}&#176;", dip);
    }
    if (const double dec = CertNum(e, "field_declination_deg"); std::isfinite(dec)) {
      field += fmt::format(", declination {:.2f}&#176;", dec);
    }
    o += CertRow("Magnetic field |B|", field);
  }
  if (const double lat = CertNum(e, "latitude_deg"); std::isfinite(lat)) {
    o += CertRow("Latitude", fmt::format("{:.4f}&#176;", lat));
  }
  const Json& t = e.value("temperature_c", Json());
  o += CertRow("Temperature", t.is_array()
                                  ? fmt::format("{:.1f} &#8230; {:.1f} &#176;C (the sensor&#8217;s "
                                                "reading)",
                                                t[0].get<double>(), t[1].get<double>())
                                  : "<span class=\"missing-info\">not recorded</span>");
  if (e.value("recorded", true) == false) {
    o += CertRow("Note", "the calibration does not record its reference vectors: defaults shown");
  }
  return o + "</table></section>";
}

// "16 at &#177;33.3, &#177;100 &#176;/s about the inner, middle, outer axes": a rate whose
// negative was held too is written once with &#177;.
std::string CertRates(const Json& poses) {
  const int segments = poses.value("rate_segments", 0);
  if (segments == 0) return "none";
  std::vector<double> rates;
  for (const Json& r : poses["rates_dps"]) {
    if (r.is_number()) rates.push_back(r.get<double>());
  }
  auto held = [&](double v) {
    return std::any_of(rates.begin(), rates.end(), [&](double r) { return r == v; });
  };
  std::string text;
  for (double r : rates) {
    if (r < 0 && held(-r)) continue;  // written as the positive one's +-
    const std::string sign = r > 0 && held(-r) ? "&#177;" : (r > 0 ? "+" : "");
    text += fmt::format("{}{}{:.3g}", text.empty() ? "" : ", ", sign, r);
  }
  std::string axes;
  for (const Json& a : poses["rate_axes"]) {
    axes += (axes.empty() ? "" : ", ") + Escape(a.is_string() ? a.get<std::string>() : "");
  }
  return fmt::format("{} at {} &#176;/s about the {} axis{}", segments, text, axes,
                     poses["rate_axes"].size() > 1 ? "es" : "");
}

std::string CertProcedure(const Json& c) {
  const Json& p = c["procedure"];
  const Json& poses = p["poses"];
  std::string o = "<section><h2>Procedure</h2><table class=\"kv\">";
  if (p.value("pose_source", "") == "free") {
    o += CertRow("Method", "without a turntable: static intervals found in a free tumble");
    o += CertRow("Static intervals", fmt::format("{}", p.value("records", 0)));
  } else {
    o += CertRow("Method", fmt::format("turntable, {} static poses ({} orientations)",
                                       poses.value("static_poses", 0),
                                       poses.value("distinct_orientations", 0)));
    std::string angles;
    const char* labels[3][2] = {
        {"phi_deg", "&#966;"}, {"gamma_deg", "&#947;"}, {"psi_deg", "&#968;"}};
    for (const auto& [key, label] : labels) {
      if (!poses["angle_ranges_deg"].contains(key)) continue;
      const Json& r = poses["angle_ranges_deg"][key];
      if (!r[0].is_number() || !r[1].is_number()) continue;
      angles += fmt::format("{}{} {:g}&#8230;{:g}&#176;", angles.empty() ? "" : ", ", label,
                            r[0].get<double>(), r[1].get<double>());
    }
    if (!angles.empty()) o += CertRow("Table angles", angles);
    o += CertRow("Rate segments", CertRates(poses));
  }
  if (const double dwell = CertNum(p, "dwell_s_median"); std::isfinite(dwell)) {
    std::string text = fmt::format("{:.2f} s (median of {})", dwell, p.value("records", 0));
    if (const double session = CertNum(p, "session_s"); std::isfinite(session)) {
      text += fmt::format(", {:.0f} s in all", session);
    }
    if (p.value("clock", "") == "sensor") text += " (the device's clock)";
    o += CertRow("Dwell per pose", text);
  }
  const Json& k = p["calibrator"];
  std::string model = Escape(CertText(k, "sensor_class"));
  model += model.empty() ? "" : " class";
  // The triad's unit: the magnetometer's is the device's own.
  const std::string sensor = CertText(c["calibration"], "sensor");
  const char* unit = sensor == "accelerometer" ? "m/s&#178;"
                     : sensor == "gyroscope"   ? "rad/s"
                                               : "(device unit)";
  if (const double n = CertNum(k, "noise_density"); std::isfinite(n) && n > 0) {
    model += fmt::format("; white noise {:.3g} {}/&#8730;Hz", n, unit);
  }
  if (const std::string loss = CertText(k, "loss"); !loss.empty()) {
    model += "; " + Escape(loss) + " loss";
    if (const double s = CertNum(k, "loss_scale"); std::isfinite(s)) {
      model += fmt::format(" ({:g}&#963;)", s);
    }
  }
  if (const double tau = CertNum(k, "drift_gauss_markov_tau_s"); std::isfinite(tau)) {
    const Json& s = k["drift_gauss_markov_sigma"];
    if (s.is_array() && !s.empty() && s[0].is_number()) {
      model += fmt::format("; bias Gauss&#8211;Markov {:.3g} {}, &#964; {:g} s", s[0].get<double>(),
                           unit, tau);
    }
  }
  if (!model.empty()) o += CertRow("Noise model", model);
  return o + "</table></section>";
}

std::string CertParameterRow(const Json& p) {
  const Json& s = p["shown"];
  const std::string check = CertText(p, "check");
  const std::string unit = CertText(s, "unit");
  const double U = CertNum(s, "U");
  const int decimals = CertDecimalsFor(U);
  // The value to the last digit of U (two significant digits): what the uncertainty supports.
  const double value = CertNum(s, "value");
  const std::string value_text =
      std::isfinite(U) ? CertFixed(value, decimals) : CertUnsigned(fmt::format("{:.6g}", value));
  std::string row = fmt::format(
      R"(<tr id="param-{}" class="{}"><td class="name">{}</td><td class="kind">{}</td><td>{}</td>)",
      Escape(CertText(p, "name")),
      check == "within"           ? "within"
      : check == "exceeds"        ? "exceeds"
      : check == "not determined" ? "undetermined"
                                  : "ungated",
      Escape(CertText(p, "name")), Escape(CertText(p, "kind")),
      CertWithUnit(value_text, CertText(s, "value_unit")));
  if (std::isfinite(U)) {
    const double u = CertNum(s, "u");
    row += "<td>" + CertWithUnit(CertFixed(u, CertDecimalsFor(u)), unit) + "</td><td>" +
           CertWithUnit(CertFixed(U, decimals), unit) + "</td>";
  } else {
    row += R"(<td class="nd" colspan="2">not determined</td>)";
  }
  const double tolerance = CertNum(s, "tolerance_u");
  row += "<td>" +
         (std::isfinite(tolerance) ? CertWithUnit(fmt::format("{:.3g}", tolerance), unit)
                                   : std::string("&#8212;")) +
         "</td>";
  std::string verdict = "reported, not gated";
  if (check == "within") verdict = "u &#8804; T &#10003;";
  if (check == "exceeds") verdict = "u &gt; T &#10007;";
  if (check == "not determined")
    verdict = std::isfinite(tolerance) ? "no u: fails &#10007;" : "&#8212;";
  return row + "<td class=\"check\">" + verdict + "</td></tr>";
}

// "value ± U" in the shown unit, U to two significant digits (or the value alone when U is not
// stated).
std::string CertValuePlusU(const Json& shown, const std::string& value_unit) {
  const double value = CertNum(shown, "value"), U = CertNum(shown, "U");
  if (!std::isfinite(U)) {
    return CertWithUnit(CertUnsigned(fmt::format("{:.6g}", value)), value_unit) +
           R"( <span class="nd">(U not stated)</span>)";
  }
  const int decimals = CertDecimalsFor(U);
  const std::string unit = CertText(shown, "unit");
  return CertWithUnit(CertFixed(value, decimals), value_unit) + " &#177; " +
         CertWithUnit(CertFixed(U, decimals), unit);
}

// "unit/degC^j" as printed.
std::string CertPerDegree(const std::string& unit) {
  const std::size_t at = unit.find("/degC");
  if (at == std::string::npos) return CertUnit(unit);
  const std::string power = unit.substr(at + 5);
  return CertUnit(unit.substr(0, at)) + "/&#176;C" +
         (power == "^2"   ? "&#178;"
          : power == "^3" ? "&#179;"
                          : Escape(power));
}

// A calibration over temperature: each parameter at the range's ends and at T0, its worst u over
// the range against the tolerance, and the polynomials' coefficients.
std::string CertThermalResults(const Json& c) {
  const Json& t = c["temperature"];
  const double lo = CertNum(t, "t_min_c"), hi = CertNum(t, "t_max_c"), t0 = CertNum(t, "t0_c");
  std::string o = fmt::format(
      "<h2>Results over temperature</h2><p class=\"statement\">Each parameter is a polynomial in "
      "the sensor&#8217;s temperature T (the die&#8217;s, as the device reports it), p(T) = "
      "&#931;<sub>j</sub> c<sub>j</sub> (T &#8722; T0)<sup>j</sup>, calibrated over "
      "<strong>{:.1f} &#8230; {:.1f} &#176;C</strong> (T0 = {:.1f} &#176;C; {} poses at {} "
      "distinct temperatures). Outside this range the station uses the parameters at the nearer "
      "end and flags the samples; this certificate states nothing there.</p>",
      lo, hi, t0, t.value("poses", 0), t.value("distinct_temperatures", 0));
  o += fmt::format(
      "<table class=\"params thermal\"><thead><tr><th>Parameter</th><th>Order</th><th>At {:.1f} "
      "&#176;C &#177; U (k&#8201;=&#8201;2)</th><th>At T0 = {:.1f} &#176;C &#177; U</th><th>At "
      "{:.1f} &#176;C &#177; U</th><th>Largest u over the range</th><th>Tolerance T on u</th><th "
      "class=\"left\">Gate check (largest u)</th></tr></thead><tbody>",
      lo, t0, hi);
  for (const Json& p : c["parameters"]) {
    const Json& s = p["shown"];
    const std::string check = CertText(p, "check");
    const std::string vu = CertText(s, "value_unit"), unit = CertText(s, "unit");
    const double worst = CertNum(s, "u_worst"), tolerance = CertNum(s, "tolerance_u");
    std::string verdict = "not gated";
    if (check == "within") verdict = "&#8804; T &#10003;";
    if (check == "exceeds") verdict = "&gt; T &#10007;";
    if (check == "not determined") verdict = "no u: fails &#10007;";
    o += fmt::format(
        R"(<tr id="param-{0}" class="{1}"><td class="name">{0}</td><td>{2}</td><td>{3}</td>)"
        R"(<td>{4}</td><td>{5}</td><td>{6}</td><td>{7}</td><td class="check">{8}</td></tr>)",
        Escape(CertText(p, "name")),
        check == "within"    ? "within"
        : check == "exceeds" ? "exceeds"
                             : (check == "not determined" ? "undetermined" : "ungated"),
        p.value("order", 0), CertValuePlusU(p["t_min"]["shown"], vu), CertValuePlusU(s, vu),
        CertValuePlusU(p["t_max"]["shown"], vu),
        std::isfinite(worst) ? CertWithUnit(CertFixed(worst, CertDecimalsFor(worst)), unit) +
                                   fmt::format("<br>at {:.1f} &#176;C", CertNum(p, "u_worst_at_c"))
                             : std::string("&#8212;"),
        std::isfinite(tolerance) ? CertWithUnit(fmt::format("{:.3g}", tolerance), unit)
                                 : std::string("&#8212;"),
        verdict);
  }
  o += "</tbody></table><h2>Coefficients</h2><table class=\"params\"><thead><tr><th>"
       "Coefficient</th><th>Value</th><th>u (k&#8201;=&#8201;1)</th><th>U "
       "(k&#8201;=&#8201;2)</th></tr></thead><tbody>";
  for (const Json& k : t["coefficients"]) {
    const Json& s = k["shown"];
    const double u = CertNum(s, "u"), U = CertNum(s, "U");
    const std::string unit = CertText(s, "unit");
    const int decimals = CertDecimalsFor(U);
    o += fmt::format(
        "<tr><td class=\"name\">{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
        Escape(CertText(k, "name")),
        std::isfinite(U) ? CertFixed(CertNum(s, "value"), decimals) + CertPerDegree(unit)
                         : CertUnsigned(fmt::format("{:.6g}", CertNum(s, "value"))),
        std::isfinite(u) ? CertFixed(u, CertDecimalsFor(u)) + CertPerDegree(unit)
                         : std::string("not determined"),
        std::isfinite(U) ? CertFixed(U, decimals) + CertPerDegree(unit) : std::string("&#8212;"));
  }
  o += "</tbody></table><p class=\"statement\"><strong>Uncertainty.</strong> u: standard "
       "uncertainty (1&#963;) of each parameter at that temperature, from the covariance of all "
       "the coefficients. U = k&#183;u with k = 2 (about 95 % for a normal distribution; GUM, "
       "JCGM 100:2008). <strong>Tolerance.</strong> The publish gate compares the largest u over "
       "the calibrated range (41 temperatures, the ends included) with T. Values are rounded to "
       "the last digit of U; the data embedded in this file hold them unrounded, in SI units per "
       "&#176;C<sup>j</sup>.";
  if (!t.value("covariance_complete", true)) {
    o += " The calibration does not hold the coefficients&#8217; whole covariance: u is stated at "
         "T0 only.";
  }
  return o + "</p>";
}

std::string CertResults(const Json& c) {
  if (c.contains("temperature")) return CertThermalResults(c);
  std::string o =
      "<h2>Results</h2><table class=\"params\"><thead><tr><th>Parameter</th>"
      "<th class=\"left\">Kind</th><th>Value</th><th>u (k&#8201;=&#8201;1)</th><th>U "
      "(k&#8201;=&#8201;2)</th>"
      "<th>Tolerance T on u</th><th class=\"left\">Gate check</th></tr></thead><tbody>";
  for (const Json& p : c["parameters"]) o += CertParameterRow(p);
  o += "</tbody></table>";
  o += "<p class=\"statement\"><strong>Uncertainty.</strong> u: standard uncertainty (1&#963;, "
       "from the calibration&#8217;s covariance). U = k&#183;u: expanded uncertainty, coverage "
       "factor k = 2, a coverage probability of about 95 % for a normal distribution (GUM, JCGM "
       "100:2008). Values are rounded to the last digit of U; the data embedded in this file hold "
       "them unrounded, in SI units. <strong>Tolerance.</strong> The publish gate compares u (not "
       "U) with T: a gated parameter passes when u &#8804; T; installation and mounting "
       "parameters of the case frame are reported, not gated. <em>Not determined</em>: the poses "
       "do not determine the parameter (unobservable, or fixed by the model&#8217;s gauge); no "
       "uncertainty is stated. Units: ppm for scale factors, degrees, mg (1 g = 9.80665 "
       "m/s&#178;), mG when the device reports Gauss, &#176;/h.";
  if (c["procedure"].value("tolerances_recorded", true) == false) {
    o += " The calibration does not record its tolerances: the industrial class&#8217;s are "
         "shown.";
  }
  return o + "</p>";
}

std::string CertVerdict(const Json& c) {
  const Json& v = c["verdict"];
  const Json& f = c["fit"];
  const bool pass = v.value("pass", false);
  std::string o = fmt::format(
      R"(<section class="verdict"><h2>Verdict</h2><p class="verdict-line">Publish gate: )"
      R"(<strong class="{}">{}</strong>)",
      pass ? "pass" : "fail", pass ? "PASS" : "NOT PASSED");
  if (pass && c["procedure"].value("pose_source", "") == "turntable") {
    o += " &#8212; <span class=\"notes\">every gated parameter within tolerance, &#967;&#178; "
         "consistent with the noise, no extreme pose</span>";
  } else if (pass) {
    o += " &#8212; <span class=\"notes\">every gated parameter within tolerance</span>";
  }
  o += "</p>";
  if (v.contains("override") && v["override"].is_object()) {
    const Json& w = v["override"];
    o += fmt::format(
        "<p><strong>Published by operator override</strong>: {} &#8212; &#8220;{}&#8221;</p>",
        Escape(CertText(w, "operator")), Escape(CertText(w, "reason")));
  }
  if (!v["reasons"].empty()) o += "<p>Reasons:</p>" + CertList(v["reasons"], "reasons");
  if (!v["missing"].empty()) {
    o += "<p>Not determined by the poses:</p>" + CertList(v["missing"], "missing");
  }
  const double chi2 = CertNum(f, "chi2"), dof = CertNum(f, "dof");
  std::string fit = fmt::format("&#967;&#178; = {:.2f} for {:g} degrees of freedom", chi2, dof);
  if (dof > 0) fit += fmt::format(" (&#967;&#178;/dof = {:.3f})", chi2 / dof);
  if (const double p = CertNum(f, "p_value"); std::isfinite(p))
    fit += fmt::format(", p = {:.3g}", p);
  if (const double rank = CertNum(f, "rank"); std::isfinite(rank)) {
    fit += fmt::format("; rank {:g} of {}", rank, f.value("parameters", 0));
  }
  o += "<p>Fit: " + fit + ".";
  // The fit check's message after its own "chi2/dof = ... (p = ...): ", which the line has.
  if (std::string m = CertText(f, "message"); !m.empty()) {
    if (const std::size_t colon = m.find("): "); colon != std::string::npos) m.erase(0, colon + 3);
    if (!m.empty()) m[0] = static_cast<char>(std::toupper(static_cast<unsigned char>(m[0])));
    o += " " + Escape(m) + ".";
  }
  if (const std::string g = CertText(f, "gauge"); !g.empty()) o += " Gauge: " + Escape(g) + ".";
  o += "</p>";
  // The gate's notes but those on parameters it does not gate: the table shows them.
  Json notes = Json::array();
  for (const Json& n : v["notes"]) {
    const std::string text = n.is_string() ? n.get<std::string>() : n.dump();
    const std::string suffix = "; not gated";
    if (text.size() < suffix.size() ||
        text.compare(text.size() - suffix.size(), suffix.size(), suffix) != 0) {
      notes.push_back(text);
    }
  }
  if (!notes.empty()) o += "<div class=\"notes\">Notes:" + CertList(notes, "notes") + "</div>";
  return o + "</section>";
}

std::string CertFooter(const Json& c) {
  return fmt::format(
      "<footer><p>Calibrated with turncal {}; certificate rendered by {}.</p>"
      "<p>Content hash (SHA-256): <span class=\"hash\" id=\"content-hash\">{}</span></p>"
      "<p>The hash covers every byte of this HTML file, its own 64 digits replaced by zeros; "
      "<code>turncal certificate --verify FILE.html</code> recomputes it, and any change fails. "
      "It shows that the file is unchanged since turncal wrote it, not who wrote it: it is not a "
      "signature. A printed or PDF copy shows the hash of its HTML file.</p></footer>",
      Escape(CertText(c["calibration"], "software")), Escape(c.value("renderer", "")),
      kCertificateHashPlaceholder);
}

// The data block: JSON inside <script type="application/json">, which a browser never runs.
// '<' is written as \u003c so that no "</script>" can end the block early.
std::string CertDataBlock(const Json& c) {
  const std::string json = c.dump(1, ' ', /*ensure_ascii=*/true);
  std::string safe;
  for (char ch : json) safe += ch == '<' ? std::string("\\u003c") : std::string(1, ch);
  return "<script type=\"application/json\" id=\"turncal-certificate-data\">\n" + safe +
         "\n</script>\n";
}

}  // namespace

bool RenderCertificateHtml(const CertificateSource& source, std::string* html,
                           std::string* hash_hex, std::string* error) {
  Json c;
  if (!CertificateContent(source, &c, error)) return false;
  const std::string number = c.value("number", "");
  std::string page =
      "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
      "<meta name=\"turncal-certificate-sha256\" content=\"" +
      std::string(kCertificateHashPlaceholder) +
      "\">\n"
      "<meta name=\"turncal-certificate-number\" content=\"" +
      Escape(number) + "\">\n<title>Calibration certificate " + Escape(number) +
      "</title>\n<style>" + kCertStyle + "</style>\n</head>\n<body>\n<main class=\"sheet\">\n" +
      CertHeader(c) + "\n<div class=\"facts\">" + CertInstrument(c) + CertCalibration(c) +
      CertEnvironment(c) + CertProcedure(c) + "</div>\n" + CertResults(c) + "\n" + CertVerdict(c) +
      "\n" + DriftSectionHtml(c.value("drift", Json()), CertText(c["calibration"], "model")) +
      CertFooter(c) + "\n" + CertDataBlock(c) + "</main>\n</body>\n</html>\n";
  // The hash over the page with the placeholder, then written where the placeholder stands
  // for it: the <meta> and the footer (a placeholder anywhere else stays, and is hashed as is).
  const std::string hash = Sha256Hex(page);
  const std::string placeholder = kCertificateHashPlaceholder;
  for (const std::string& before : {std::string("name=\"turncal-certificate-sha256\" content=\""),
                                    std::string("id=\"content-hash\">")}) {
    const std::size_t at = page.find(before + placeholder);
    if (at != std::string::npos) page.replace(at + before.size(), placeholder.size(), hash);
  }
  *html = std::move(page);
  *hash_hex = hash;
  return true;
}

}  // namespace turncal::report
