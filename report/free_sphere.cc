#include "report/free_sphere.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "report/svg.h"

namespace turncal::report {

std::optional<SphereValues> BeforeAfterValues(const FreeReportInput& in, const FreeModelResult& r,
                                              std::size_t max_values) {
  const FreeEstimate& fe = r.estimate;
  if (!fe.estimate.ok || fe.estimate.theta.size() == 0) return std::nullopt;
  std::string error;
  const auto model = MakeFreeModel(r.model, in.context, &error);
  if (!model) return std::nullopt;
  const SensorKind triad = model->sensor();
  if (triad != SensorKind::kMagnetometer && triad != SensorKind::kAccelerometer) {
    return std::nullopt;
  }
  std::vector<Eigen::Vector3d> raw;
  const auto take = [&](const FreeInterval& iv) {
    const auto& s = triad == SensorKind::kMagnetometer ? iv.mag : iv.acc;
    if (s && s->count > 0 && s->mean.allFinite()) raw.push_back(s->mean);
  };
  for (const FreeInterval& iv : in.found.intervals) take(iv);
  if (in.motion && triad == SensorKind::kMagnetometer) {
    for (const FreeInterval& p : in.motion->points) take(p);
  }
  if (raw.empty()) return std::nullopt;
  SphereValues v;
  v.of = static_cast<std::int64_t>(raw.size());
  const std::size_t stride = std::max<std::size_t>(1, (raw.size() + max_values - 1) / max_values);
  for (std::size_t i = 0; i < raw.size(); i += stride) {
    const Eigen::Vector3d after = model->Correct(fe.estimate.theta, raw[i]);
    if (!after.allFinite()) continue;
    v.before.push_back(raw[i]);
    v.after.push_back(after);
  }
  if (triad == SensorKind::kMagnetometer) {
    v.radius = in.context.field_magnitude > 0 ? in.context.field_magnitude : 1.0;
    v.unit = in.context.field_magnitude > 0 ? "the field's unit" : "relative";
    v.distortion = "the hard and soft iron";
  } else {
    v.radius = in.context.gravity_mps2;
    v.unit = "m/s^2";
    v.distortion = "the biases, gains and misalignments";
  }
  if (v.before.empty()) return std::nullopt;
  return v;
}

std::string BeforeAfterSvg(const SphereValues& v, const std::string& id) {
  const double P = 240, gap = 30, top = 64;
  double extent = v.radius;
  for (const auto* set : {&v.before, &v.after}) {
    for (const auto& x : *set) extent = std::max(extent, x.cwiseAbs().maxCoeff());
  }
  extent *= 1.08;
  const int axes[3][2] = {{0, 1}, {0, 2}, {1, 2}};
  const char* names = "xyz";
  std::string o = svg::Open(
      id, 3 * P + 2 * gap, P + top + 30, "The values before and after calibration",
      fmt::format("{} of {} values: raw in grey, corrected in red, the sphere of radius {} ({}) "
                  "as a dashed circle",
                  v.before.size(), v.of, svg::Num(v.radius), v.unit));
  o += fmt::format(
      "<text x=\"0\" y=\"14\">before: the raw values (grey), squashed into an ellipsoid by "
      "{}</text>\n<text x=\"0\" y=\"32\">after: the same corrected (red), on the dashed sphere "
      "of radius {} {}</text>\n<text x=\"0\" y=\"50\">{} of {} values drawn</text>\n",
      svg::Escape(v.distortion), svg::Num(v.radius),
      svg::Escape(v.unit == "relative" ? "(relative: no field given)" : v.unit), v.before.size(),
      v.of);
  for (int k = 0; k < 3; ++k) {
    const double x0 = k * (P + gap), cx = x0 + P / 2, cy = top + P / 2, s = P / 2 / extent;
    const int a = axes[k][0], b = axes[k][1];
    o += fmt::format(
        "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"#fafafa\" stroke=\"#888\"/>\n",
        svg::Num(x0), svg::Num(top), svg::Num(P), svg::Num(P));
    o += fmt::format(
        "<line x1=\"{0}\" y1=\"{1}\" x2=\"{2}\" y2=\"{1}\" stroke=\"#ccc\"/><line x1=\"{3}\" "
        "y1=\"{4}\" x2=\"{3}\" y2=\"{5}\" stroke=\"#ccc\"/>\n",
        svg::Num(x0), svg::Num(cy), svg::Num(x0 + P), svg::Num(cx), svg::Num(top),
        svg::Num(top + P));
    o += fmt::format(
        "<circle cx=\"{}\" cy=\"{}\" r=\"{}\" fill=\"none\" stroke=\"#333\" "
        "stroke-dasharray=\"4 3\"/>\n",
        svg::Num(cx), svg::Num(cy), svg::Num(v.radius * s));
    o += fmt::format(
        "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{} (right) and {} (up)</text>\n",
        svg::Num(cx), svg::Num(top + P + 16), names[a], names[b]);
    for (int set = 0; set < 2; ++set) {
      for (const auto& x : set == 0 ? v.before : v.after) {
        o += fmt::format("<circle class=\"{}\" cx=\"{}\" cy=\"{}\" r=\"1.5\" fill=\"{}\"/>\n",
                         set == 0 ? "before" : "after", svg::Num(cx + s * x[a]),
                         svg::Num(cy - s * x[b]), set == 0 ? "#999" : "#c0392b");
      }
    }
  }
  o += svg::Close();
  return o;
}

}  // namespace turncal::report
