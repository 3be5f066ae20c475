#pragma once
// The little SVG the calibration report needs (inline in HTML, no script): escaping, axis
// scales with readable ticks, framed panels, a palette. Coordinates are SVG user units (px).

#include <string>
#include <string_view>
#include <vector>

namespace turncal::report::svg {

// Text and attribute values for HTML and SVG: & < > " ' replaced by entities.
std::string Escape(std::string_view text);

// A coordinate or number as short text ("12.5", "-3"); "0" for non-finite values.
std::string Num(double v);

// A data axis mapped onto [px_lo, px_hi] (px_hi < px_lo for a y axis pointing up). A log axis
// needs lo > 0.
struct Scale {
  double lo = 0.0, hi = 1.0;
  bool log = false;
  double px_lo = 0.0, px_hi = 1.0;
  double operator()(double v) const;
  bool Contains(double v) const;  // v within [lo, hi] (and > 0 on a log axis)
};

// Ticks at 1, 2, 5 x 10^n (linear) or at decades (log), inside [lo, hi].
std::vector<double> Ticks(const Scale& scale);
std::string TickLabel(double v);

// [lo, hi] grown to include 0 when `with_zero`, widened when empty, with 5 % margins.
void PadRange(double* lo, double* hi, bool with_zero);

struct Panel {
  double x = 0, y = 0, w = 100, h = 100;  // the plotting area
  Scale sx, sy;
};
Panel MakePanel(double x, double y, double w, double h, double x_lo, double x_hi, double y_lo,
                double y_hi, bool y_log);

// Frame, grid, ticks with labels, the panel's title above it and the axis labels.
void DrawAxes(const Panel& panel, std::string_view title, std::string_view x_label,
              std::string_view y_label, std::string* out);

// <svg class="plot" id=...> with its <title> and <desc>, and the closing tag.
std::string Open(std::string_view id, double width, double height, std::string_view title,
                 std::string_view description);
std::string Close();

// Distinguishable colours (cycled) and dash patterns (cycled every palette length).
const char* Color(int i);
const char* Dash(int i);

}  // namespace turncal::report::svg
