#include "drivers/capture/text_log.h"

#include <fmt/format.h>

#include <charconv>
#include <cmath>
#include <fstream>
#include <optional>
#include <set>

namespace turncal::drivers {

namespace {

// The fields of a line, split at commas, semicolons, tabs and blanks (runs of blanks are one
// separator; a comma or semicolon between blanks too).
std::vector<std::string_view> Fields(std::string_view line) {
  std::vector<std::string_view> out;
  std::size_t i = 0;
  const auto blank = [](char c) { return c == ' ' || c == '\t' || c == '\r'; };
  const auto separator = [](char c) { return c == ',' || c == ';'; };
  while (i < line.size()) {
    while (i < line.size() && blank(line[i])) ++i;
    if (i >= line.size()) break;
    std::size_t j = i;
    while (j < line.size() && !blank(line[j]) && !separator(line[j])) ++j;
    out.push_back(line.substr(i, j - i));
    while (j < line.size() && blank(line[j])) ++j;
    if (j < line.size() && separator(line[j])) ++j;
    i = j;
  }
  return out;
}

bool Number(std::string_view field, double* value) {
  if (!field.empty() && field.front() == '+') field.remove_prefix(1);
  const auto [end, ec] = std::from_chars(field.data(), field.data() + field.size(), *value);
  return ec == std::errc() && end == field.data() + field.size() && std::isfinite(*value);
}

bool TriadValid(const TriadColumns& t, const char* name, std::string* error) {
  const int present = (t.column[0] >= 0) + (t.column[1] >= 0) + (t.column[2] >= 0);
  if (present != 0 && present != 3) {
    *error = fmt::format("the {} needs three columns (x, y, z) or none", name);
    return false;
  }
  if (present == 3 && (!std::isfinite(t.scale) || t.scale == 0 || !std::isfinite(t.offset))) {
    *error = fmt::format("the {}'s scale must be finite and nonzero, its offset finite", name);
    return false;
  }
  return true;
}

}  // namespace

bool TextLogLayout::IsValid(std::string* error) const {
  std::string why;
  if (time_column < 0) {
    why = "the log needs a time column";
  } else if (!std::isfinite(time_scale) || !(time_scale > 0)) {
    why = "the time scale must be finite and > 0";
  } else if (!acc.present() && !gyr.present() && !mag.present()) {
    why = "the log needs at least one triad's columns";
  } else if (TriadValid(acc, "accelerometer", &why) && TriadValid(gyr, "gyroscope", &why) &&
             TriadValid(mag, "magnetometer", &why)) {
    std::set<int> seen = {time_column};
    for (const TriadColumns* t : {&acc, &gyr, &mag}) {
      for (int c : t->column) {
        if (c >= 0 && !seen.insert(c).second) why = fmt::format("column {} is named twice", c + 1);
      }
    }
  }
  if (!why.empty() && error) *error = why;
  return why.empty();
}

bool ParseColumnSpec(const std::string& spec, TextLogLayout* layout, std::string* error) {
  TextLogLayout l = *layout;
  l.time_column = -1;
  l.acc.column = l.gyr.column = l.mag.column = {-1, -1, -1};
  int index = 0;
  std::size_t start = 0;
  while (start <= spec.size()) {
    const std::size_t comma = std::min(spec.find(',', start), spec.size());
    const std::string name = spec.substr(start, comma - start);
    if (name == "t") {
      if (l.time_column >= 0) {
        if (error) *error = "columns: 't' named twice";
        return false;
      }
      l.time_column = index;
    } else if (name.size() == 2 && (name[0] == 'a' || name[0] == 'g' || name[0] == 'm') &&
               name[1] >= 'x' && name[1] <= 'z') {
      TriadColumns& t = name[0] == 'a' ? l.acc : name[0] == 'g' ? l.gyr : l.mag;
      int& c = t.column[static_cast<std::size_t>(name[1] - 'x')];
      if (c >= 0) {
        if (error) *error = fmt::format("columns: '{}' named twice", name);
        return false;
      }
      c = index;
    } else if (name != "-") {
      if (error) {
        *error = fmt::format(
            "columns: unknown name '{}' (t, ax ay az, gx gy gz, mx my mz, or - to skip)", name);
      }
      return false;
    }
    ++index;
    start = comma + 1;
  }
  if (!l.IsValid(error)) return false;
  *layout = l;
  return true;
}

double TextLogStats::rate_hz() const {
  return samples > 1 && t_last_s > t_first_s
             ? static_cast<double>(samples - 1) / (t_last_s - t_first_s)
             : 0.0;
}

bool ReadTextLog(std::istream& in, const TextLogLayout& layout, const std::string& device,
                 std::vector<Sample>* out, TextLogStats* stats, std::string* error) {
  if (!layout.IsValid(error)) return false;
  int needed = layout.time_column;
  for (const TriadColumns* t : {&layout.acc, &layout.gyr, &layout.mag}) {
    for (int c : t->column) needed = std::max(needed, c);
  }
  TextLogStats s;
  std::string line;
  double t0 = 0.0, last = -INFINITY;
  auto skip = [&](const std::string& why) {
    ++s.skipped;
    if (s.first_skipped.empty()) s.first_skipped = fmt::format("line {}: {}", s.lines, why);
  };
  while (std::getline(in, line)) {
    ++s.lines;
    const std::vector<std::string_view> f = Fields(line);
    if (f.empty()) continue;  // a blank line
    if (!f[0].empty() && (f[0].front() == '#' || f[0].front() == '%')) {
      skip("a comment");
      continue;
    }
    if (static_cast<int>(f.size()) <= needed) {
      skip(fmt::format("{} fields, the layout needs {}", f.size(), needed + 1));
      continue;
    }
    double time = 0.0;
    if (!Number(f[static_cast<std::size_t>(layout.time_column)], &time)) {
      skip("the time is not a number");
      continue;
    }
    Sample sample;
    bool ok = true;
    auto triad = [&](const TriadColumns& t) -> std::optional<Eigen::Vector3d> {
      if (!t.present()) return std::nullopt;
      Eigen::Vector3d v;
      for (int k = 0; k < 3; ++k) {
        double x = 0.0;
        if (!Number(f[static_cast<std::size_t>(t.column[static_cast<std::size_t>(k)])], &x)) {
          ok = false;
          return std::nullopt;
        }
        v[k] = (x - t.offset) * t.scale;
      }
      return v;
    };
    sample.acc_mps2 = triad(layout.acc);
    sample.gyr_radps = triad(layout.gyr);
    sample.mag = triad(layout.mag);
    if (!ok) {
      skip("a triad's value is not a number");
      continue;
    }
    const double t_s = time * layout.time_scale;
    if (!(t_s > last)) {
      ++s.backwards;
      continue;
    }
    if (s.samples == 0) {
      t0 = t_s;
      s.t_first_s = t_s;
    }
    last = t_s;
    s.t_last_s = t_s;
    sample.device = device;
    sample.t_device_s = t_s;
    sample.t_host_ns = static_cast<std::int64_t>(std::llround((t_s - t0) * 1e9));
    sample.counter = static_cast<std::uint32_t>(s.samples);
    out->push_back(std::move(sample));
    ++s.samples;
  }
  if (stats) *stats = s;
  if (s.samples == 0) {
    if (error) {
      *error = fmt::format("no line of {} is a sample{}", s.lines,
                           s.first_skipped.empty() ? "" : " (" + s.first_skipped + ")");
    }
    return false;
  }
  return true;
}

bool ReadTextLogFile(const std::string& path, const TextLogLayout& layout,
                     const std::string& device, std::vector<Sample>* out, TextLogStats* stats,
                     std::string* error) {
  std::ifstream in(path);
  if (!in) {
    if (error) *error = fmt::format("cannot open {}", path);
    return false;
  }
  std::string why;
  if (!ReadTextLog(in, layout, device, out, stats, &why)) {
    if (error) *error = fmt::format("{}: {}", path, why);
    return false;
  }
  return true;
}

bool ReadImuTkPair(const std::string& acc_path, const std::string& gyr_path, TriadColumns acc,
                   TriadColumns gyr, const std::string& device, std::vector<Sample>* out,
                   TextLogStats* stats, std::string* error) {
  acc.column = {1, 2, 3};
  gyr.column = {1, 2, 3};
  TextLogLayout la, lg;
  la.acc = acc;
  lg.gyr = gyr;
  std::vector<Sample> a, g;
  TextLogStats sa, sg;
  if (!ReadTextLogFile(acc_path, la, device, &a, &sa, error) ||
      !ReadTextLogFile(gyr_path, lg, device, &g, &sg, error)) {
    return false;
  }
  if (a.size() != g.size()) {
    if (error) {
      *error = fmt::format("{} has {} samples, {} has {}: not one recording", acc_path, a.size(),
                           gyr_path, g.size());
    }
    return false;
  }
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (std::abs(*a[i].t_device_s - *g[i].t_device_s) > 1e-6) {
      if (error) {
        *error = fmt::format("sample {}: the accelerometer's time {} and the gyro's {} differ", i,
                             *a[i].t_device_s, *g[i].t_device_s);
      }
      return false;
    }
    a[i].gyr_radps = g[i].gyr_radps;
  }
  if (stats) {
    *stats = sa;
    stats->lines += sg.lines;
    stats->skipped += sg.skipped;
    stats->backwards += sg.backwards;
    if (stats->first_skipped.empty() && !sg.first_skipped.empty()) {
      stats->first_skipped = gyr_path + " " + sg.first_skipped;
    }
  }
  out->insert(out->end(), std::make_move_iterator(a.begin()), std::make_move_iterator(a.end()));
  return true;
}

}  // namespace turncal::drivers
