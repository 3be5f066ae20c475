#include "report/svg.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace turncal::report::svg {

std::string Escape(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&#39;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

std::string Num(double v) {
  if (!std::isfinite(v)) return "0";
  return fmt::format("{:.1f}", v);
}

double Scale::operator()(double v) const {
  double t;
  if (log) {
    t = (std::log10(v) - std::log10(lo)) / (std::log10(hi) - std::log10(lo));
  } else {
    t = (v - lo) / (hi - lo);
  }
  return px_lo + t * (px_hi - px_lo);
}

bool Scale::Contains(double v) const {
  return std::isfinite(v) && v >= lo && v <= hi && (!log || v > 0);
}

std::vector<double> Ticks(const Scale& s) {
  std::vector<double> ticks;
  if (!(s.hi > s.lo)) return ticks;
  if (s.log) {
    for (int e = static_cast<int>(std::ceil(std::log10(s.lo) - 1e-9));
         e <= static_cast<int>(std::floor(std::log10(s.hi) + 1e-9)); ++e) {
      ticks.push_back(std::pow(10.0, e));
    }
    return ticks;
  }
  const double raw = (s.hi - s.lo) / 5;
  const double decade = std::pow(10.0, std::floor(std::log10(raw)));
  double step = decade;
  for (double m : {1.0, 2.0, 5.0, 10.0}) {
    step = m * decade;
    if (step >= raw) break;
  }
  for (double v = std::ceil(s.lo / step) * step; v <= s.hi + 1e-9 * step; v += step) {
    ticks.push_back(std::abs(v) < 1e-9 * step ? 0.0 : v);
  }
  return ticks;
}

std::string TickLabel(double v) {
  if (v == 0) return "0";
  const double a = std::abs(v);
  if (a >= 1e5 || a < 1e-3) return fmt::format("{:.0e}", v);
  return fmt::format("{:g}", v);
}

void PadRange(double* lo, double* hi, bool with_zero) {
  if (with_zero) {
    *lo = std::min(*lo, 0.0);
    *hi = std::max(*hi, 0.0);
  }
  if (!std::isfinite(*lo) || !std::isfinite(*hi)) {
    *lo = -1;
    *hi = 1;
  }
  if (*hi - *lo <= 1e-300) {
    const double d = std::max(std::abs(*lo), 1.0) * 0.5;
    *lo -= d;
    *hi += d;
  }
  const double m = 0.05 * (*hi - *lo);
  *lo -= m;
  *hi += m;
}

Panel MakePanel(double x, double y, double w, double h, double x_lo, double x_hi, double y_lo,
                double y_hi, bool y_log) {
  Panel p;
  p.x = x;
  p.y = y;
  p.w = w;
  p.h = h;
  p.sx = Scale{x_lo, x_hi, false, x, x + w};
  p.sy = Scale{y_lo, y_hi, y_log, y + h, y};
  return p;
}

void DrawAxes(const Panel& p, std::string_view title, std::string_view x_label,
              std::string_view y_label, std::string* out) {
  std::string& o = *out;
  o += fmt::format(R"(<rect class="frame" x="{}" y="{}" width="{}" height="{}"/>)", Num(p.x),
                   Num(p.y), Num(p.w), Num(p.h));
  for (double t : Ticks(p.sy)) {
    const double y = p.sy(t);
    o += fmt::format(R"(<line class="grid" x1="{}" y1="{}" x2="{}" y2="{}"/>)", Num(p.x), Num(y),
                     Num(p.x + p.w), Num(y));
    o += fmt::format(R"(<text class="tick" x="{}" y="{}" text-anchor="end">{}</text>)",
                     Num(p.x - 4), Num(y + 4), Escape(TickLabel(t)));
  }
  for (double t : Ticks(p.sx)) {
    const double x = p.sx(t);
    o += fmt::format(R"(<line class="grid" x1="{}" y1="{}" x2="{}" y2="{}"/>)", Num(x), Num(p.y),
                     Num(x), Num(p.y + p.h));
    o += fmt::format(R"(<text class="tick" x="{}" y="{}" text-anchor="middle">{}</text>)", Num(x),
                     Num(p.y + p.h + 14), Escape(TickLabel(t)));
  }
  if (!title.empty()) {
    o += fmt::format(R"(<text class="panel-title" x="{}" y="{}" text-anchor="middle">{}</text>)",
                     Num(p.x + p.w / 2), Num(p.y - 6), Escape(title));
  }
  if (!x_label.empty()) {
    o += fmt::format(R"(<text class="label" x="{}" y="{}" text-anchor="middle">{}</text>)",
                     Num(p.x + p.w / 2), Num(p.y + p.h + 30), Escape(x_label));
  }
  if (!y_label.empty()) {
    const double x = p.x - 46, y = p.y + p.h / 2;
    o += fmt::format(
        R"~(<text class="label" x="{}" y="{}" text-anchor="middle" transform="rotate(-90 {} {})">{}</text>)~",
        Num(x), Num(y), Num(x), Num(y), Escape(y_label));
  }
}

std::string Open(std::string_view id, double width, double height, std::string_view title,
                 std::string_view description) {
  return fmt::format(
      R"(<svg class="plot" id="{0}" xmlns="http://www.w3.org/2000/svg" width="{1}" height="{2}" )"
      R"(viewBox="0 0 {1} {2}" role="img" aria-labelledby="{0}-title {0}-desc">)"
      R"(<title id="{0}-title">{3}</title><desc id="{0}-desc">{4}</desc>)",
      Escape(id), Num(width), Num(height), Escape(title), Escape(description));
}

std::string Close() { return "</svg>\n"; }

const char* Color(int i) {
  static const char* const kPalette[] = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd",
                                         "#ff7f0e", "#17becf", "#8c564b", "#e377c2",
                                         "#7f7f7f", "#bcbd22", "#393b79", "#637939"};
  constexpr int n = sizeof(kPalette) / sizeof(kPalette[0]);
  return kPalette[((i % n) + n) % n];
}

const char* Dash(int i) {
  static const char* const kDashes[] = {"none", "6 3", "2 2", "8 3 2 3"};
  return kDashes[(std::max(i, 0) / 12) % 4];
}

}  // namespace turncal::report::svg
