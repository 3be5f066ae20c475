#include "core/frames/mount.h"

#include "core/frames/units.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>

namespace turncal {
namespace {

// "+x" -> 0 with sign +1; false for anything else.
bool ParseSignedAxis(std::string_view s, int* axis, double* sign) {
  if (s.size() != 2 || (s[0] != '+' && s[0] != '-')) return false;
  if (s[1] < 'x' || s[1] > 'z') return false;
  *axis = s[1] - 'x';
  *sign = s[0] == '-' ? -1.0 : 1.0;
  return true;
}

// The name of a unit vector along a case axis or a diagonal ("+z", "(+x-y)", "(+x+y+z)").
std::optional<std::string> DirectionName(const Eigen::Vector3d& u) {
  for (int n = 1; n <= 3; ++n) {
    // The nearest direction with n entries of +-1/sqrt(n): the n largest |u_i|.
    Eigen::Vector3d v = Eigen::Vector3d::Zero();
    int order[3] = {0, 1, 2};
    std::sort(order, order + 3, [&](int a, int b) { return std::abs(u[a]) > std::abs(u[b]); });
    for (int k = 0; k < n; ++k) v[order[k]] = u[order[k]] >= 0 ? 1.0 : -1.0;
    v.normalize();
    if (std::acos(std::min(1.0, v.dot(u))) > 2.0 * kRadPerDeg) continue;
    std::string name;
    for (int i = 0; i < 3; ++i) {
      if (v[i] == 0) continue;
      name += v[i] > 0 ? '+' : '-';
      name += static_cast<char>('x' + i);
    }
    return n == 1 ? name : "(" + name + ")";
  }
  return std::nullopt;
}

std::string Fixed(double v, int digits) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", digits,
                std::abs(v) < 0.5 * std::pow(10, -digits) ? 0.0 : v);
  return buf;
}

}  // namespace

bool ParseMountAxes(std::string_view text, Mat3<double>* mount, std::string* error) {
  const auto fail = [&](const std::string& why) {
    if (error) {
      *error = "mount '" + std::string(text) + "': " + why +
               " (three signed axes: the case's x, y and z along the table's, e.g. \"+x+y+z\" "
               "or \"-y+x+z\")";
    }
    return false;
  };
  if (text.size() != 6) return fail("not three signed axes");
  Mat3<double> m = Mat3<double>::Zero();
  for (int row = 0; row < 3; ++row) {
    int axis = 0;
    double sign = 1;
    if (!ParseSignedAxis(text.substr(static_cast<std::size_t>(2 * row), 2), &axis, &sign)) {
      return fail("'" + std::string(text.substr(static_cast<std::size_t>(2 * row), 2)) +
                  "' is not a signed axis (+x, -y, ...)");
    }
    m(row, axis) = sign;
  }
  if (!((m.transpose() * m - Mat3<double>::Identity()).norm() < 1e-12)) {
    return fail("an axis is named twice");
  }
  if (m.determinant() < 0) return fail("the axes are left-handed (a mirror, not a rotation)");
  *mount = m;
  return true;
}

bool ParseMountText(std::string_view text, Mat3<double>* mount, std::string* error) {
  const bool axes = !text.empty() && (text[0] == '+' || text[0] == '-') &&
                    text.find_first_of("xyz") != std::string_view::npos;
  if (axes) return ParseMountAxes(text, mount, error);
  double deg[3];
  char tail = 0;
  const std::string s(text);
  if (std::sscanf(s.c_str(), "%lf,%lf,%lf%c", &deg[0], &deg[1], &deg[2], &tail) == 3 &&
      std::isfinite(deg[0]) && std::isfinite(deg[1]) && std::isfinite(deg[2])) {
    *mount = MountFromAnglesDeg(deg[0], deg[1], deg[2]);
    return true;
  }
  if (error) {
    *error = "mount '" + s +
             "': the case's axes along the table's (\"+x+y+z\", \"-y+x+z\", ...) or X,Y,Z in "
             "degrees";
  }
  return false;
}

Mat3<double> MountFromAnglesDeg(double x_deg, double y_deg, double z_deg) {
  return R1(x_deg * kRadPerDeg) * R2(y_deg * kRadPerDeg) * R3(z_deg * kRadPerDeg);
}

std::optional<std::string> MountAxesName(const Mat3<double>& mount) {
  std::string name;
  for (int row = 0; row < 3; ++row) {
    int found = -1;
    for (int col = 0; col < 3; ++col) {
      const double v = mount(row, col);
      if (std::abs(std::abs(v) - 1.0) <= 1e-6) {
        if (found >= 0) return std::nullopt;
        found = col;
        name += v > 0 ? '+' : '-';
        name += static_cast<char>('x' + col);
      } else if (std::abs(v) > 1e-6) {
        return std::nullopt;
      }
    }
    if (found < 0) return std::nullopt;
  }
  return mount.determinant() > 0 ? std::optional<std::string>(name) : std::nullopt;
}

Eigen::Vector3d MountAnglesDeg(const Mat3<double>& m) {
  // R1(x) R2(y) R3(z): m(0,2) = -sin y, m(0,0) = cos y cos z, m(0,1) = cos y sin z,
  // m(1,2) = sin x cos y, m(2,2) = cos x cos y.
  const double y = std::asin(std::clamp(-m(0, 2), -1.0, 1.0));
  double x = 0, z = 0;
  if (std::cos(y) > 1e-9) {
    x = std::atan2(m(1, 2), m(2, 2));
    z = std::atan2(m(0, 1), m(0, 0));
  } else {
    // Gimbal lock: only x - z (y = +90) or x + z (y = -90) is defined; x = 0.
    z = std::atan2(-m(1, 0), m(1, 1));
  }
  return Eigen::Vector3d(x, y, z) * kDegPerRad;
}

std::string MountConfigText(const Mat3<double>& mount) {
  if (const auto name = MountAxesName(mount)) return "\"" + *name + "\"";
  const Eigen::Vector3d a = MountAnglesDeg(mount);
  return "[" + Fixed(a.x(), 3) + ", " + Fixed(a.y(), 3) + ", " + Fixed(a.z(), 3) + "]";
}

MountRotation RotationOf(const Mat3<double>& d) {
  // D maps the configured case's coordinates to the observed case's (a frame rotation): the
  // observed axes are the rows of D, the active rotation that turns the configured axes into them
  // is D^T.
  const Eigen::AngleAxisd aa(Mat3<double>(d.transpose()));
  MountRotation out;
  out.angle_deg = aa.angle() * kDegPerRad;
  out.axis = aa.axis();
  if (out.angle_deg > 179.999) {
    // 180 deg about u is 180 deg about -u: the axis with its largest entry positive.
    Eigen::Index i = 0;
    out.axis.cwiseAbs().maxCoeff(&i);
    if (out.axis[i] < 0) out.axis = -out.axis;
  }
  return out;
}

std::string DescribeMountRotation(const Mat3<double>& d) {
  const MountRotation r = RotationOf(d);
  if (r.angle_deg < 0.05) return "as configured";
  const std::optional<std::string> named = DirectionName(r.axis);
  const std::string axis = named ? *named
                                 : "(" + Fixed(r.axis.x(), 3) + ", " + Fixed(r.axis.y(), 3) + ", " +
                                       Fixed(r.axis.z(), 3) + ")";
  std::string text =
      "rotated " + Fixed(r.angle_deg, r.angle_deg > 10 ? 0 : 1) + " deg about its " + axis;
  // Upside down: the case's z turned over.
  if (std::abs(r.angle_deg - 180.0) < 1.0 && std::abs(r.axis.z()) < 0.05) text += " (upside down)";
  return text;
}

}  // namespace turncal
