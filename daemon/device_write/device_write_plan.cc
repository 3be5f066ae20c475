#include "daemon/device_write/device_write_plan.h"

#include <fmt/format.h>

#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>

#include "core/frames/reference.h"
#include "drivers/mip/mip_stored.h"
#include "drivers/mip/mip_stored_write.h"

namespace turncal::daemon {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// A quantity to write, with what the device holds now (to_write and sigma come later).
StoredWrite Planned(std::uint8_t descriptor, std::vector<double> stored) {
  return {drivers::mip::StoredQuantityKey(descriptor), descriptor, std::move(stored), {}, {},
          drivers::mip::StoredQuantityUnit(descriptor)};
}

double F32(double v) { return static_cast<double>(static_cast<float>(v)); }

std::vector<double> Values(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }
std::vector<double> Values(const Eigen::Matrix3d& m) {
  std::vector<double> out;
  for (int i = 0; i < 9; ++i) out.push_back(m(i / 3, i % 3));
  return out;
}

// The same f32 value (what the device holds) for every entry.
bool SameF32(const std::optional<Eigen::Vector3d>& a, const std::optional<Eigen::Vector3d>& b) {
  if (a.has_value() != b.has_value()) return false;
  if (!a) return true;
  for (int i = 0; i < 3; ++i) {
    if (F32((*a)[i]) != F32((*b)[i])) return false;
  }
  return true;
}
bool SameF32(const std::optional<Eigen::Matrix3d>& a, const std::optional<Eigen::Matrix3d>& b) {
  if (a.has_value() != b.has_value()) return false;
  if (!a) return true;
  for (int i = 0; i < 9; ++i) {
    if (F32((*a)(i / 3, i % 3)) != F32((*b)(i / 3, i % 3))) return false;
  }
  return true;
}

std::string Vec(const Eigen::Vector3d& v, double scale, int digits) {
  return fmt::format("({:+.{}f}, {:+.{}f}, {:+.{}f})", v.x() * scale, digits, v.y() * scale, digits,
                     v.z() * scale, digits);
}

// R P, R a rotation and P symmetric positive definite; false for a reflection.
bool Polar(const Eigen::Matrix3d& A, Eigen::Matrix3d* R, Eigen::Matrix3d* P) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(A, Eigen::ComputeFullU | Eigen::ComputeFullV);
  *R = svd.matrixU() * svd.matrixV().transpose();
  *P = svd.matrixV() * svd.singularValues().asDiagonal() * svd.matrixV().transpose();
  return R->determinant() > 0;
}

// The values to write (unrounded), in the plan's order, from the correction's A and c.
using Composition = std::function<std::vector<double>(const AffineCorrection&)>;

}  // namespace

TriadCorrection CorrectionOf(const MeasurementModel& model) {
  TriadCorrection c;
  c.name = model.name();
  c.sensor = model.sensor();
  c.scale = model.excitation_ned().norm();
  c.correct = [&model](const Eigen::VectorXd& theta, const Eigen::Vector3d& m) {
    return model.Correct(theta, m);
  };
  if (model.index_of("Bg_xx") >= 0) c.also_in_stream = "the gyroscope's g-sensitivity";
  return c;
}

TriadCorrection CorrectionOf(const FreeModel& model, double scale) {
  TriadCorrection c;
  c.name = model.name();
  c.sensor = model.sensor();
  c.scale = scale;
  c.correct = [&model](const Eigen::VectorXd& theta, const Eigen::Vector3d& m) {
    return model.Correct(theta, m);
  };
  if (model.index_of("g11") >= 0) c.also_in_stream = "the gyroscope's g-sensitivity";
  return c;
}

bool AffineCorrectionOf(const MeasurementModel& model, const Eigen::VectorXd& theta,
                        AffineCorrection* out, std::string* error) {
  return AffineCorrectionOf(CorrectionOf(model), theta, out, error);
}

bool AffineCorrectionOf(const TriadCorrection& model, const Eigen::VectorXd& theta,
                        AffineCorrection* out, std::string* error) {
  double s = model.scale;
  if (!(s > 0) || !std::isfinite(s)) s = 1.0;
  AffineCorrection a;
  a.c = model.correct(theta, Eigen::Vector3d::Zero());
  for (int i = 0; i < 3; ++i) {
    a.A.col(i) = (model.correct(theta, s * Eigen::Vector3d::Unit(i)) - a.c) / s;
  }
  const Eigen::Vector3d p = s * Eigen::Vector3d(0.3, -0.7, 0.5);
  const Eigen::Vector3d y = model.correct(theta, p);
  if (!y.allFinite() || !a.A.allFinite() || !a.c.allFinite() ||
      (y - (a.A * p + a.c)).norm() > 1e-9 * (y.norm() + s)) {
    *error = fmt::format("{}'s correction is not affine in the sample", model.name);
    return false;
  }
  if (!(std::abs(a.A.determinant()) > 1e-9)) {
    *error = fmt::format("{}'s correction is singular", model.name);
    return false;
  }
  *out = a;
  return true;
}

std::optional<drivers::mip::StoredCalibration> StoredCalibrationFromIdentity(
    const nlohmann::json& identity) {
  if (!identity.is_object() || !identity.contains("stored_calibration")) return std::nullopt;
  const nlohmann::json& s = identity["stored_calibration"];
  if (!s.is_object()) return std::nullopt;
  drivers::mip::StoredCalibration out;
  std::string error;
  if (!drivers::mip::ParseStoredCalibration(s, &out, &error)) return std::nullopt;
  return out;
}

namespace {

// What the steps of a plan share: the request, the correction's affine form and polar rotation,
// the device's transform before, and what is planned so far.
struct Planning {
  Planning(const DeviceWriteRequest& request, TriadCorrection correction, DeviceWritePlan& out)
      : q(request), model(std::move(correction)), plan(out) {}
  const DeviceWriteRequest& q;
  const TriadCorrection model;
  DeviceWritePlan& plan;
  AffineCorrection a;
  Eigen::Matrix3d M_old = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d R_model = Eigen::Matrix3d::Identity(), P_model = Eigen::Matrix3d::Identity();
  std::vector<StoredWrite> writes;
  Composition compose;
  void refuse(std::string why) { plan.refusals.push_back(std::move(why)); }
};

// The request itself: the protocol, the gate, the serial, what the device stored then and now.
// False when nothing can be planned (refused).
bool CheckRequest(Planning& g, const std::optional<TriadCorrection>& given) {
  const DeviceWriteRequest& q = g.q;
  DeviceWritePlan& plan = g.plan;
  auto refuse = [&](std::string why) { g.refuse(std::move(why)); };
  if (q.protocol == drivers::Protocol::kXbus || q.protocol == drivers::Protocol::kXbusLegacy) {
    refuse(
        "an Xsens device: no public Xbus message writes a user magnetometer or inertial "
        "calibration; turncald keeps correcting in its stream");
    return false;
  }
  if (q.protocol == drivers::Protocol::kGx2) {
    refuse(
        "a 3DM-GX2 (single-byte protocol): turncal writes calibrations only with MIP's 3DM "
        "commands; turncald keeps correcting in its stream");
    return false;
  }
  if (!given || !given->correct) {
    refuse("no calibration");
    return false;
  }
  if (!q.gate_passed) refuse(fmt::format("{} v{} has not passed its gate", plan.model, q.version));
  if (q.serial_then.empty()) {
    refuse("the calibration does not record the device's serial (a replay?)");
  } else if (q.serial_then != q.serial_now) {
    refuse(fmt::format("the calibration was made on serial {}, the device is serial {}",
                       q.serial_then, q.serial_now));
  }
  const drivers::mip::StoredCalibration& now = q.stored_now;
  if (!q.stored_then) {
    refuse("the calibration does not record what the device stored when it was made");
  } else if (!SameF32(q.stored_then->accel_bias, now.accel_bias) ||
             !SameF32(q.stored_then->gyro_bias, now.gyro_bias) ||
             !SameF32(q.stored_then->hard_iron, now.hard_iron) ||
             !SameF32(q.stored_then->soft_iron, now.soft_iron) ||
             // A calibration recorded before turncal read the transform says nothing of it.
             (q.stored_then->transform && !SameF32(q.stored_then->transform, now.transform))) {
    refuse(
        "the device stores other values than when the calibration was made (written or restored "
        "since): calibrate again");
  }
  return true;
}

// An accelerometer's or gyroscope's bias (0x37, 0x38); the rest stays in the stream.
bool PlanBias(Planning& g, SensorKind kind) {
  const DeviceWriteRequest& q = g.q;
  const TriadCorrection& model = g.model;
  DeviceWritePlan& plan = g.plan;
  const drivers::mip::StoredCalibration& now = q.stored_now;
  const AffineCorrection& a = g.a;
  const Eigen::Matrix3d& M_old = g.M_old;
  const Eigen::Matrix3d& R_model = g.R_model;
  std::vector<StoredWrite>& writes = g.writes;
  Composition& compose = g.compose;
  auto refuse = [&](std::string why) { g.refuse(std::move(why)); };
  const bool acc = kind == SensorKind::kAccelerometer;
  const std::optional<Eigen::Vector3d>& old = acc ? now.accel_bias : now.gyro_bias;
  if (!old) {
    refuse(fmt::format("the device has no {} bias command (it answered \"unknown command\")",
                       acc ? "accelerometer" : "gyro"));
    return false;
  }
  const double unit = acc ? kStandardGravity_mps2 : 1.0;
  const Eigen::Vector3d old_value = *old;
  writes.push_back(Planned(acc ? std::uint8_t{0x37} : std::uint8_t{0x38}, Values(old_value)));
  compose = [old_value, unit, M_old](const AffineCorrection& x) {
    const Eigen::Vector3d b = -x.A.inverse() * x.c;
    return Values(Eigen::Vector3d(old_value + M_old.inverse() * b / unit));
  };
  const Eigen::Vector3d b = -a.A.inverse() * a.c;
  // New output m' = M_new M_old^-1 (m - b): y = A m' without the transform, A R^T with it.
  plan.stream.A = q.transform ? Eigen::Matrix3d(a.A * R_model.transpose()) : a.A;
  plan.stream.c.setZero();
  plan.changes.push_back(fmt::format("every {} sample changes by {} {}",
                                     acc ? "accelerometer" : "gyro", Vec(-b, 1.0 / unit, 6),
                                     acc ? "g" : "rad/s"));
  plan.kept_in_stream.push_back(fmt::format(
      "the {}'s scale factors and misalignments: MIP has no command for them; turncald keeps "
      "correcting them in its stream",
      acc ? "accelerometer" : "gyroscope"));
  if (!model.also_in_stream.empty()) {
    plan.kept_in_stream.push_back(model.also_in_stream + ": likewise, in the stream");
  }
  return true;
}

// The magnetometer's hard and soft iron (0x3A, 0x3B); its rotation stays in the stream unless
// the transform is written.
bool PlanIron(Planning& g) {
  const DeviceWriteRequest& q = g.q;
  DeviceWritePlan& plan = g.plan;
  const drivers::mip::StoredCalibration& now = q.stored_now;
  const AffineCorrection& a = g.a;
  const Eigen::Matrix3d& M_old = g.M_old;
  std::vector<StoredWrite>& writes = g.writes;
  Composition& compose = g.compose;
  auto refuse = [&](std::string why) { g.refuse(std::move(why)); };
  if (!now.hard_iron || !now.soft_iron) {
    refuse(
        "the device has no hard- and soft-iron commands (it answered \"unknown command\" to "
        "0x3A or 0x3B)");
    return false;
  }
  Eigen::Matrix3d R, P;
  if (!Polar(a.A, &R, &P)) {
    refuse(fmt::format("{}'s correction is a reflection", plan.model));
    return false;
  }
  const Eigen::Matrix3d S_old = *now.soft_iron;
  const Eigen::Vector3d h_old = *now.hard_iron;
  if (!(std::abs(S_old.determinant()) > 1e-9)) {
    refuse("the stored soft-iron matrix is singular");
    return false;
  }
  writes.push_back(Planned(0x3A, Values(h_old)));
  writes.push_back(Planned(0x3B, Values(S_old)));
  // New output m' = M_new S_new (raw - h_new) = M_new M_old^-1 P (m - b) with
  // h_new = h_old + S_old^-1 M_old^-1 b and S_new = M_old^-1 P M_old S_old.
  compose = [S_old, h_old, M_old](const AffineCorrection& x) {
    Eigen::Matrix3d r, p;
    Polar(x.A, &r, &p);
    const Eigen::Vector3d b = -x.A.inverse() * x.c;
    std::vector<double> v = Values(Eigen::Vector3d(h_old + S_old.inverse() * M_old.inverse() * b));
    const std::vector<double> m = Values(Eigen::Matrix3d(M_old.inverse() * p * M_old * S_old));
    v.insert(v.end(), m.begin(), m.end());
    return v;
  };
  const Eigen::Vector3d b = -a.A.inverse() * a.c;
  const Eigen::Vector3d sv = Eigen::JacobiSVD<Eigen::Matrix3d>(P).singularValues();
  const double angle_deg = std::acos(std::clamp((R.trace() - 1.0) / 2.0, -1.0, 1.0)) * 180.0 / M_PI;
  plan.stream.A = q.transform ? Eigen::Matrix3d::Identity().eval() : R;
  plan.stream.c.setZero();
  plan.changes.push_back(
      fmt::format("the magnetometer's output: offset {} Gauss at zero field, scale {:+.3f} % to "
                  "{:+.3f} % along the soft iron's axes",
                  Vec(-P * b, 1.0, 5), (sv.minCoeff() - 1) * 100, (sv.maxCoeff() - 1) * 100));
  if (!q.transform) {
    plan.kept_in_stream.push_back(fmt::format(
        "the rotation between the magnetometer's axes and the frame {} corrects into ({:.3f} "
        "deg): writing it would turn the device's output frame (--transform does); turncald "
        "keeps it in its stream",
        plan.model, angle_deg));
  }
  return true;
}

// --transform: the sensor-to-vehicle transform (0x33) turned by the correction's rotation.
void PlanTransform(Planning& g) {
  DeviceWritePlan& plan = g.plan;
  const Eigen::Matrix3d& R_model = g.R_model;
  const Eigen::Matrix3d M_old = g.M_old;
  std::vector<StoredWrite>& writes = g.writes;
  Composition& compose = g.compose;
  // With the transform: the device's output turns by R (the rotation of the calibration's
  // correction) on top of what it stores, M_new = R M_old.
  const auto transform_values = [M_old](const AffineCorrection& x) {
    Eigen::Matrix3d r, p;
    Polar(x.A, &r, &p);
    return Values(Eigen::Matrix3d(r * M_old));
  };
  const double turn_deg =
      std::acos(std::clamp((R_model.trace() - 1.0) / 2.0, -1.0, 1.0)) * 180.0 / M_PI;
  writes.push_back(Planned(0x33, Values(M_old)));
  const Composition triad = compose;
  compose = [triad, transform_values](const AffineCorrection& x) {
    std::vector<double> v = triad(x);
    const std::vector<double> m = transform_values(x);
    v.insert(v.end(), m.begin(), m.end());
    return v;
  };
  plan.changes.push_back(fmt::format(
      "every output of the device (accelerometer, gyroscope, magnetometer) turns by {:.3f} deg "
      "(sensor-to-vehicle transform): it outputs in the frame {} corrects into; turncald "
      "re-expresses the output for the device's other calibrations",
      turn_deg, plan.model));
}

// The values to write, rounded to f32, with their sigma through the composition's Jacobian
// (central differences of the composition over the calibration's covariance).
void FillValues(Planning& g) {
  const DeviceWriteRequest& q = g.q;
  const TriadCorrection& model = g.model;
  const AffineCorrection& a = g.a;
  const Composition& compose = g.compose;
  std::vector<StoredWrite>& writes = g.writes;
  auto refuse = [&](std::string why) { g.refuse(std::move(why)); };
  const std::vector<double> values = compose(a);
  std::vector<double> sigma(values.size(), kNaN);
  const int n = static_cast<int>(q.theta.size());
  if (q.covariance.rows() == n && q.covariance.cols() == n && q.covariance.allFinite()) {
    Eigen::MatrixXd J(static_cast<Eigen::Index>(values.size()), n);
    bool ok = true;
    for (int j = 0; j < n && ok; ++j) {
      const double sj = std::sqrt(std::max(q.covariance(j, j), 0.0));
      const double h = sj > 0 ? 1e-3 * sj : 1e-7 * std::max(1.0, std::abs(q.theta[j]));
      Eigen::VectorXd plus = q.theta, minus = q.theta;
      plus[j] += h;
      minus[j] -= h;
      AffineCorrection ap, am;
      std::string e;
      ok = AffineCorrectionOf(model, plus, &ap, &e) && AffineCorrectionOf(model, minus, &am, &e);
      if (!ok) break;
      const std::vector<double> vp = compose(ap), vm = compose(am);
      for (std::size_t i = 0; i < values.size(); ++i) {
        J(static_cast<Eigen::Index>(i), j) = (vp[i] - vm[i]) / (2 * h);
      }
    }
    if (ok) {
      const Eigen::MatrixXd C = J * q.covariance * J.transpose();
      for (std::size_t i = 0; i < values.size(); ++i) {
        sigma[i] =
            std::sqrt(std::max(C(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(i)), 0.0));
      }
    }
  }
  std::size_t k = 0;
  for (StoredWrite& w : writes) {
    for (std::size_t i = 0; i < w.stored.size(); ++i, ++k) {
      const double v = F32(values[k]);
      if (!std::isfinite(v)) {
        refuse(fmt::format("{}: a value to write is not finite (or beyond a float)", w.quantity));
      }
      w.to_write.push_back(v);
      w.sigma.push_back(sigma[k]);
    }
  }
}

}  // namespace

DeviceWritePlan PlanDeviceWrite(const DeviceWriteRequest& q) {
  DeviceWritePlan plan;
  plan.device = q.device;
  std::optional<TriadCorrection> given = q.correction;
  if (q.model) given = CorrectionOf(*q.model);
  plan.model = given ? given->name : "";
  plan.serial = q.serial_now;
  plan.version = q.version;
  Planning g(q, given ? *given : TriadCorrection{}, plan);
  if (!CheckRequest(g, given)) return plan;
  std::string error;
  if (!AffineCorrectionOf(g.model, q.theta, &g.a, &error)) {
    g.refuse(error);
    return plan;
  }
  const drivers::mip::StoredCalibration& now = q.stored_now;
  // The device turns its output by its sensor-to-vehicle transform M after its own calibration.
  g.M_old = now.transform.value_or(Eigen::Matrix3d::Identity());
  if (!(std::abs(g.M_old.determinant()) > 1e-9)) {
    g.refuse("the stored sensor-to-vehicle transform is singular");
    return plan;
  }
  if (q.transform && !now.transform) {
    g.refuse(
        "the device has no sensor-to-vehicle transform command (it answered \"unknown command\" "
        "to 0x33)");
    return plan;
  }
  if (!Polar(g.a.A, &g.R_model, &g.P_model)) {
    g.refuse(fmt::format("{}'s correction is a reflection", plan.model));
    return plan;
  }
  const SensorKind kind = g.model.sensor;
  const bool planned = kind == SensorKind::kAccelerometer || kind == SensorKind::kGyroscope
                           ? PlanBias(g, kind)
                           : PlanIron(g);
  if (!planned) return plan;
  if (q.transform) PlanTransform(g);
  FillValues(g);
  plan.writes = std::move(g.writes);
  return plan;
}

nlohmann::json JsonNumbers(const std::vector<double>& values) {
  nlohmann::json a = nlohmann::json::array();
  for (double x : values) a.push_back(std::isfinite(x) ? nlohmann::json(x) : nlohmann::json());
  return a;
}

nlohmann::json ToJson(const DeviceWritePlan& plan) {
  nlohmann::json writes = nlohmann::json::array();
  for (const StoredWrite& w : plan.writes) {
    writes.push_back({{"quantity", w.quantity},
                      {"name", drivers::mip::StoredQuantityName(w.descriptor)},
                      {"descriptor", fmt::format("0x0C 0x{:02X}", w.descriptor)},
                      {"stored", JsonNumbers(w.stored)},
                      {"to_write", JsonNumbers(w.to_write)},
                      {"sigma", JsonNumbers(w.sigma)},
                      {"unit", w.unit}});
  }
  nlohmann::json stream_A = nlohmann::json::array();
  for (int r = 0; r < 3; ++r) {
    stream_A.push_back({plan.stream.A(r, 0), plan.stream.A(r, 1), plan.stream.A(r, 2)});
  }
  return {{"device", plan.device},
          {"model", plan.model},
          {"version", plan.version},
          {"serial", plan.serial},
          {"ok", plan.ok()},
          {"refusals", plan.refusals},
          {"writes", writes},
          {"changes", plan.changes},
          {"kept_in_stream", plan.kept_in_stream},
          {"stream_correction",
           {{"A", stream_A}, {"c", {plan.stream.c.x(), plan.stream.c.y(), plan.stream.c.z()}}}}};
}

}  // namespace turncal::daemon
