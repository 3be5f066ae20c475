#include "report/device_writes.h"

#include <fmt/format.h>

#include "report/svg.h"

namespace turncal::report {

using svg::Escape;

namespace {

std::string Values(const nlohmann::json& v) {
  if (!v.is_array()) return "";
  std::string out;
  for (const auto& x : v) {
    out += out.empty() ? "" : " ";
    out += x.is_number() ? fmt::format("{:.7g}", x.get<double>()) : std::string("&#8212;");
  }
  return out;
}

}  // namespace

std::string DeviceWritesHtml(const std::vector<nlohmann::json>& entries) {
  if (entries.empty()) return "";
  std::string o =
      "<section class=\"device-writes\" id=\"device-writes\"><h2>Written into the device</h2>"
      "<p>What turncal wrote into the device's stored calibration, read back bit for bit and "
      "verified by measurement: the device's uncorrected output after the write against the "
      "output predicted from before it (docs/protocol.md &#8220;Writing a calibration into the "
      "device&#8221;). Scale factors and misalignments stay in turncald's stream.</p>"
      "<table><tr><th>time</th><th>operation</th><th>calibration</th><th>outcome</th>"
      "<th>values written</th><th>verification</th></tr>";
  for (const auto& e : entries) {
    if (!e.is_object()) continue;
    std::string written;
    const nlohmann::json plan = e.value("plan", nlohmann::json::object());
    for (const auto& w : plan.value("writes", nlohmann::json::array())) {
      written += fmt::format("{}{} ({}): {}", written.empty() ? "" : "<br>",
                             Escape(w.value("name", w.value("quantity", ""))),
                             Escape(w.value("unit", "")), Values(w["to_write"]));
    }
    const nlohmann::json v = e.value("verification", nlohmann::json());
    std::string verification = "&#8212;";
    if (v.is_object()) {
      verification =
          fmt::format("<span class=\"{}\">{}</span>", v.value("pass", false) ? "pass" : "fail",
                      Escape(v.value("summary", std::string())));
    }
    const bool ok = e.value("ok", false);
    std::string outcome = Escape(e.value("state", "")) + (e.value("save", false) ? " (save)" : "");
    if (!ok && !e.value("error", std::string()).empty()) {
      outcome += "<br>" + Escape(e.value("error", std::string()));
    }
    const std::string calibration =
        e.value("operation", "") == "restore"
            ? std::string("&#8212;")
            : fmt::format("{} v{}", Escape(e.value("model", "")), e.value("version", 0));
    o += fmt::format(
        "<tr class=\"device-write\"><td>{}</td><td>{}</td><td>{}</td><td class=\"{}\">{}</td>"
        "<td>{}</td><td>{}</td></tr>",
        Escape(e.value("time", "")), Escape(e.value("operation", "")), calibration,
        ok ? "pass" : "fail", outcome, written, verification);
  }
  return o + "</table></section>\n";
}

}  // namespace turncal::report
