#include "core/analysis/free_advice.h"

#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <memory>
#include <vector>

namespace turncal {
namespace {

// "+x", "-y+z", "+x+y+z" for a direction with entries in {-1, 0, 1}.
std::string Name(const Eigen::Vector3i& d) {
  std::string s;
  for (int i = 0; i < 3; ++i) {
    if (d[i] != 0) s += fmt::format("{}{}", d[i] > 0 ? '+' : '-', "xyz"[i]);
  }
  return s;
}

std::vector<Eigen::Vector3i> Directions(bool edges) {
  std::vector<Eigen::Vector3i> out;
  for (int x = -1; x <= 1; ++x) {
    for (int y = -1; y <= 1; ++y) {
      for (int z = -1; z <= 1; ++z) {
        const int n = std::abs(x) + std::abs(y) + std::abs(z);
        if (n == 0 || (n == 2 && !edges)) continue;
        out.emplace_back(x, y, z);
      }
    }
  }
  return out;
}

// The raw mean a triad's correction maps to x (every free model's correction is affine in raw).
struct Inverse {
  Eigen::Matrix3d L_inv;
  Eigen::Vector3d c0;
  Eigen::Vector3d operator()(const Eigen::Vector3d& x) const { return L_inv * (x - c0); }
};
Inverse InverseOf(const FreeModel& model, const Eigen::VectorXd& theta) {
  Inverse inv;
  inv.c0 = model.Correct(theta, Eigen::Vector3d::Zero());
  Eigen::Matrix3d L;
  for (int i = 0; i < 3; ++i) L.col(i) = model.Correct(theta, Eigen::Vector3d::Unit(i)) - inv.c0;
  inv.L_inv = L.inverse();
  return inv;
}

// The statistics of a typical interval (the median count) for `triad`, to copy the noise from.
std::optional<TriadStats> Typical(const FreeData& data, SensorKind triad) {
  std::vector<const TriadStats*> all;
  for (const auto& iv : data.intervals) {
    const auto& s = triad == SensorKind::kAccelerometer ? iv.acc
                    : triad == SensorKind::kGyroscope   ? iv.gyr
                                                        : iv.mag;
    if (s) all.push_back(&*s);
  }
  if (all.empty()) return std::nullopt;
  std::sort(all.begin(), all.end(), [](auto a, auto b) { return a->count < b->count; });
  return *all[all.size() / 2];
}

TriadStats WithMean(TriadStats s, const Eigen::Vector3d& mean) {
  s.mean = mean;
  return s;
}

double MinEigen(const Eigen::MatrixXd& F) {
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(F);
  return std::max(0.0, eig.eigenvalues()[0]);
}

}  // namespace

std::optional<OrientationAdvice> NextOrientation(const FreeModel& model, const FreeData& data,
                                                 const FreeEstimate& estimate) {
  if (!estimate.estimate.ok || data.intervals.empty()) return std::nullopt;
  const Eigen::VectorXd& theta = estimate.estimate.theta;
  const Eigen::VectorXd scales = model.Scales(data, theta);
  auto information = [&](const FreeData& d) {
    const Eigen::MatrixXd J = FreeJacobian(model, d, theta) * scales.asDiagonal();
    return Eigen::MatrixXd(J.transpose() * J);
  };
  const double before = MinEigen(information(data));
  const FreeContext& ctx = data.context;
  std::string error;

  // The accelerometer's correction: the model's own, its upstream's, or the joint model's head.
  std::unique_ptr<FreeModel> accel = MakeFreeModel("accel9", ctx, &error);
  Eigen::VectorXd accel_theta;
  if (model.name() == "accel9") {
    accel_theta = theta;
  } else if (model.upstream() == "accel9") {
    accel_theta = data.upstream_theta;
  } else if (model.name() == "accmag") {
    accel_theta = theta.head(9);
  }
  const std::optional<TriadStats> acc = Typical(data, SensorKind::kAccelerometer);
  const std::optional<TriadStats> gyr = Typical(data, SensorKind::kGyroscope);
  const std::optional<TriadStats> mag = Typical(data, SensorKind::kMagnetometer);

  struct Candidate {
    std::string text;
    Eigen::Vector3d axis;
    std::vector<FreeInterval> added;
  };
  std::vector<Candidate> candidates;
  const SensorKind sensor = model.sensor();
  if (sensor == SensorKind::kAccelerometer && accel_theta.size() == 9 && acc) {
    const Inverse a = InverseOf(*accel, accel_theta);
    for (const auto& d : Directions(true)) {
      const Eigen::Vector3d up = d.cast<double>().normalized();
      FreeInterval iv;
      iv.acc = WithMean(*acc, a(ctx.gravity_mps2 * up));
      candidates.push_back({fmt::format("point {} up", Name(d)), up, {iv}});
    }
  } else if (sensor == SensorKind::kMagnetometer && mag) {
    const Inverse m = InverseOf(model, theta);
    const double magnitude =
        model
            .Correct(theta, data.intervals.back().mag ? data.intervals.back().mag->mean
                                                      : Eigen::Vector3d::UnitX())
            .norm();
    const double field = ctx.field_magnitude > 0 ? ctx.field_magnitude
                                                 : (std::isfinite(magnitude) ? magnitude : 1.0);
    const int dip_index = model.index_of("dip");
    const double dip = dip_index >= 0 ? theta[dip_index] : ctx.dip_deg * M_PI / 180;
    const bool with_acc = model.Needs(SensorKind::kAccelerometer);
    if (with_acc && (accel_theta.size() != 9 || !acc)) return std::nullopt;
    for (const auto& d : Directions(false)) {
      const Eigen::Vector3d up = d.cast<double>().normalized();
      const Eigen::Vector3d e1 = up.unitOrthogonal(), e2 = up.cross(e1);
      Candidate c{fmt::format("point {} up and turn it about the vertical through a full turn "
                              "(8 stops)",
                              Name(d)),
                  up,
                  {}};
      for (int k = 0; k < 8; ++k) {
        const double psi = k * M_PI / 4;
        const Eigen::Vector3d h =
            -std::sin(dip) * up + std::cos(dip) * (std::cos(psi) * e1 + std::sin(psi) * e2);
        FreeInterval iv;
        iv.mag = WithMean(*mag, m(field * h));
        if (with_acc)
          iv.acc = WithMean(*acc, InverseOf(*accel, accel_theta)(ctx.gravity_mps2 * up));
        c.added.push_back(iv);
      }
      candidates.push_back(std::move(c));
    }
  } else if (sensor == SensorKind::kGyroscope && accel_theta.size() == 9 && acc && gyr) {
    const FreeInterval& last = data.intervals.back();
    if (!last.acc) return std::nullopt;
    const Inverse a = InverseOf(*accel, accel_theta);
    const Inverse g = InverseOf(model, theta);
    const Eigen::Vector3d u = accel->Correct(accel_theta, last.acc->mean).normalized();
    const double T = 2.0, tau = 0.01;
    const int blocks = static_cast<int>(T / tau);
    for (int i = 0; i < 6; ++i) {
      const Eigen::Vector3d e = (i % 2 ? -1.0 : 1.0) * Eigen::Vector3d::Unit(i / 2);
      if (std::abs(e.dot(u)) > std::cos(30 * M_PI / 180)) continue;  // near vertical
      const Eigen::Vector3d w = e * (M_PI / 2) / T;
      MoveRecord move;
      for (int j = 0; j < blocks; ++j) {
        // Gravity's direction in the case mid-block (the case turns by +w t: a fixed vector turns
        // by -w t in it).
        const Eigen::Vector3d up_j = Eigen::AngleAxisd(-(j + 0.5) * tau * w.norm(), e) * u;
        move.increment_rad.push_back(g(w) * tau);
        move.block_s.push_back(tau);
        move.force_mps2.push_back(a(ctx.gravity_mps2 * up_j));
      }
      move.t_start_s = last.t_end_s;
      move.t_end_s = last.t_end_s + T;
      move.samples = blocks + 1;
      FreeInterval iv;
      const Eigen::Vector3d up_new = Eigen::AngleAxisd(-M_PI / 2, e) * u;
      iv.acc = WithMean(*acc, a(ctx.gravity_mps2 * up_new));
      iv.gyr = WithMean(*gyr, g(Eigen::Vector3d::Zero()));
      iv.move_in = std::move(move);
      iv.t_start_s = last.t_end_s + T;
      iv.t_end_s = iv.t_start_s + last.duration_s();
      const Eigen::Vector3i d = (i % 2 ? -1 : 1) * Eigen::Vector3i::Unit(i / 2);
      candidates.push_back({fmt::format("turn 90 deg about {} (with {} level)", Name(d),
                                        std::string(1, "xyz"[i / 2])),
                            e,
                            {iv}});
    }
  }
  if (candidates.empty()) return std::nullopt;

  std::optional<OrientationAdvice> best;
  for (auto& c : candidates) {
    FreeData d = data;
    for (auto& iv : c.added) d.intervals.push_back(iv);
    const double after = MinEigen(information(d));
    if (!best || after > best->information_after) {
      OrientationAdvice a;
      a.text = c.text;
      a.axis = c.axis;
      a.information_before = before;
      a.information_after = after;
      a.sigma_ratio = after > 0 ? std::sqrt(before / after) : 1.0;
      best = a;
    }
  }
  return best;
}

std::vector<std::optional<OrientationAdvice>> NextOrientations(
    const std::vector<FreeModelResult>& results, const std::vector<FreeInterval>& intervals,
    const FreeContext& context) {
  std::vector<std::optional<OrientationAdvice>> out;
  for (const auto& r : results) {
    std::optional<OrientationAdvice> advice;
    std::string error;
    auto model = r.estimate.estimate.ok ? MakeFreeModel(r.model, context, &error) : nullptr;
    if (model) {
      FreeData data;
      // The magnetometer's samples in motion (issue 37) only for a model of the magnetometer:
      // the others' hypothetical intervals follow the last still one (gyro9's move from it).
      for (const auto& iv : intervals) {
        if (!iv.in_motion || model->sensor() == SensorKind::kMagnetometer) {
          data.intervals.push_back(iv);
        }
      }
      data.context = context;
      for (const auto& u : results) {
        if (u.model == model->upstream() && u.estimate.estimate.ok) {
          data.upstream_theta = u.estimate.estimate.theta;
          data.upstream_covariance = u.estimate.estimate.covariance;
        }
      }
      advice = NextOrientation(*model, data, r.estimate);
    }
    out.push_back(advice);
  }
  return out;
}

std::string CoverageGapText(const CoverageGap& gap, SensorKind sensor, double dip_deg) {
  if (gap.empty()) return "";
  const std::string name = CaseDirectionName(gap.direction);
  const std::string where = sensor == SensorKind::kMagnetometer
                                ? fmt::format("along the field (north and {:.0f} deg {})",
                                              std::abs(dip_deg), dip_deg >= 0 ? "down" : "up")
                                : std::string("up");
  return fmt::format(
      "the largest region without a value is about {} (none within {:.0f} deg; {:.0f} % of the "
      "sphere empty): turn it so that {} points {}",
      name, gap.radius_deg, 100 * gap.empty_area_fraction, name, where);
}

}  // namespace turncal
