#include "daemon/device_write.h"

#include <fmt/format.h>

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>

#include "core/sequencing/stillness.h"
#include "daemon/atomic_file.h"
#include "daemon/model_pipeline.h"
#include "drivers/mip/mip_stored.h"
#include "drivers/transport/transport.h"

namespace turncal::daemon {

namespace fs = std::filesystem;

namespace {

bool SameVector(const std::optional<Eigen::Vector3d>& a, const std::optional<Eigen::Vector3d>& b) {
  return a.has_value() == b.has_value() && (!a || *a == *b);
}

fs::path WritesDir(const std::string& state_dir) { return fs::path(state_dir) / "device_writes"; }

}  // namespace

double VerifyZLimit(int axes) {
  // Two-sided normal tail: erfc(z / sqrt 2) = kVerifyFalseAlarm / axes, by bisection.
  const double p = kVerifyFalseAlarm / std::max(axes, 1);
  double lo = 0.0, hi = 10.0;
  for (int i = 0; i < 100; ++i) {
    const double mid = 0.5 * (lo + hi);
    (std::erfc(mid / std::sqrt(2.0)) > p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

bool SameStoredCalibration(const StoredCalibration& a, const StoredCalibration& b) {
  return SameVector(a.accel_bias, b.accel_bias) && SameVector(a.gyro_bias, b.gyro_bias) &&
         SameVector(a.hard_iron, b.hard_iron) &&
         a.soft_iron.has_value() == b.soft_iron.has_value() &&
         (!a.soft_iron || *a.soft_iron == *b.soft_iron) &&
         a.transform.has_value() == b.transform.has_value() &&
         (!a.transform || *a.transform == *b.transform);
}

nlohmann::json ToJson(const DeviceWriteRecord& r) {
  using drivers::mip::StoredCalibrationJson;
  return {{"schema", 1},
          {"class", "DEVICE_WRITE_RECORD"},
          {"device", r.device},
          {"serial", r.serial},
          {"model", r.model},
          {"version", r.version},
          {"time", r.time},
          {"operation", r.operation},
          {"saved", r.saved},
          {"nonvolatile_changed", r.nonvolatile_changed},
          {"as_if", StoredCalibrationJson(r.as_if)},
          {"in_device", StoredCalibrationJson(r.in_device)},
          {"replaced", StoredCalibrationJson(r.replaced)},
          {"pending", r.pending ? StoredCalibrationJson(*r.pending) : nlohmann::json()}};
}

bool ParseDeviceWriteRecord(const nlohmann::json& j, DeviceWriteRecord* out, std::string* error) {
  if (!j.is_object() || j.value("class", "") != "DEVICE_WRITE_RECORD") {
    *error = "not a device write record (class DEVICE_WRITE_RECORD)";
    return false;
  }
  DeviceWriteRecord r;
  try {
    r.device = j.at("device").get<std::string>();
    r.serial = j.at("serial").get<std::string>();
    r.model = j.value("model", "");
    r.version = j.value("version", 0);
    r.time = j.value("time", "");
    r.operation = j.value("operation", "");
    r.saved = j.value("saved", false);
    r.nonvolatile_changed = j.value("nonvolatile_changed", false);
  } catch (const nlohmann::json::exception& e) {
    *error = std::string("a device write record: ") + e.what();
    return false;
  }
  std::string why;
  for (const auto& [key, into] :
       {std::pair{"as_if", &r.as_if}, std::pair{"in_device", &r.in_device},
        std::pair{"replaced", &r.replaced}}) {
    if (!j.contains(key) || !drivers::mip::ParseStoredCalibration(j[key], into, &why)) {
      *error = fmt::format("a device write record's \"{}\": {}", key,
                           j.contains(key) ? why : std::string("missing"));
      return false;
    }
  }
  if (j.contains("pending") && !j["pending"].is_null()) {
    StoredCalibration pending;
    if (!drivers::mip::ParseStoredCalibration(j["pending"], &pending, &why)) {
      *error = "a device write record's \"pending\": " + why;
      return false;
    }
    r.pending = pending;
  }
  *out = r;
  return true;
}

bool ReadDeviceWriteRecord(const std::string& state_dir, const std::string& device,
                           DeviceWriteRecord* record, bool* exists, std::string* error) {
  const fs::path path = WritesDir(state_dir) / (device + ".json");
  std::error_code ec;
  *exists = fs::exists(path, ec);
  if (!*exists) return true;
  std::ifstream in(path);
  const nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
  std::string why;
  if (j.is_discarded() || !ParseDeviceWriteRecord(j, record, &why)) {
    *error = fmt::format("'{}': {}", path.string(), j.is_discarded() ? "not JSON" : why);
    return false;
  }
  return true;
}

bool WriteDeviceWriteRecord(const std::string& state_dir, const DeviceWriteRecord& record,
                            std::string* error) {
  std::error_code ec;
  fs::create_directories(WritesDir(state_dir), ec);
  return WriteFileAtomically((WritesDir(state_dir) / (record.device + ".json")).string(),
                             ToJson(record).dump(1) + "\n", error);
}

bool WriteDeviceWriteHistory(const std::string& state_dir, const std::string& device,
                             const nlohmann::json& entry, std::string* path, std::string* error) {
  std::error_code ec;
  fs::create_directories(WritesDir(state_dir), ec);
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  char stamp[32];
  std::strftime(stamp, sizeof(stamp), "%Y%m%dT%H%M%SZ", &tm);
  fs::path target = WritesDir(state_dir) / fmt::format("{}.{}.json", device, stamp);
  for (int n = 2; fs::exists(target, ec); ++n) {
    target = WritesDir(state_dir) / fmt::format("{}.{}-{}.json", device, stamp, n);
  }
  *path = target.string();
  return WriteFileAtomically(*path, entry.dump(1) + "\n", error);
}

std::vector<nlohmann::json> ReadDeviceWriteHistory(const std::string& state_dir,
                                                   const std::string& device) {
  std::vector<std::string> paths;
  std::error_code ec;
  const std::string prefix = device + ".";
  for (const auto& entry : fs::directory_iterator(WritesDir(state_dir), ec)) {
    const std::string name = entry.path().filename().string();
    // DEVICE.UTCTIME.json and DEVICE.UTCTIME-N.json; not DEVICE.json (the record).
    if (name.rfind(prefix, 0) == 0 && name != device + ".json" && name.size() > prefix.size() &&
        name[prefix.size()] >= '0' && name[prefix.size()] <= '9') {
      paths.push_back(entry.path().string());
    }
  }
  // By time, then by the -N suffix (DEVICE.T.json, DEVICE.T-2.json, ...).
  const auto key = [&](const std::string& path) {
    std::string stem = fs::path(path).stem().string().substr(prefix.size());
    int n = 1;
    if (const auto dash = stem.find('-'); dash != std::string::npos) {
      n = std::atoi(stem.c_str() + dash + 1);
      stem.resize(dash);
    }
    return std::pair(stem, n);
  };
  std::sort(paths.begin(), paths.end(),
            [&](const std::string& a, const std::string& b) { return key(a) < key(b); });
  std::vector<nlohmann::json> entries;
  for (const auto& path : paths) {
    std::ifstream in(path);
    nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
    if (!j.is_discarded() && j.is_object()) entries.push_back(std::move(j));
  }
  return entries;
}

void OutputWindow::Add(const Sample& s) {
  const auto add = [](Sums* t, const std::optional<Eigen::Vector3d>& v) {
    if (!v) return;
    if (t->n == 0) t->first = *v;
    const Eigen::Vector3d d = *v - t->first;
    t->sum += d;
    t->sum_sq += d.cwiseProduct(d);
    t->sum_outer += d * d.transpose();
    ++t->n;
  };
  add(&acc_, s.acc_mps2);
  add(&gyr_, s.gyr_radps);
  add(&mag_, s.mag);
  ++n_;
  if (s.t_device_s) {
    t_device_sum_s_ += *s.t_device_s;
    ++n_device_time_;
  }
  t_host_sum_s_ += static_cast<double>(s.t_host_ns) * 1e-9;
}

std::optional<Eigen::Matrix3d> OutputWindow::MeanCovariance(int triad) const {
  const Sums& t = triad == kTriadAcc ? acc_ : triad == kTriadGyr ? gyr_ : mag_;
  if (t.n < 2 || t.n != n_) return std::nullopt;
  const Eigen::Vector3d mean = t.sum / t.n;
  const Eigen::Matrix3d cov = (t.sum_outer - t.n * mean * mean.transpose()) / (t.n - 1);
  return Eigen::Matrix3d(cov / t.n);
}

double OutputWindow::MeanTimeS() const {
  if (n_ == 0) return 0.0;
  return n_device_time_ == n_ ? t_device_sum_s_ / n_ : t_host_sum_s_ / n_;
}

double WanderSigma(double sigma, double tau_s, double dt_s) {
  if (!(sigma > 0) || !(tau_s > 0)) return 0.0;
  return sigma * std::sqrt(2.0 * (1.0 - std::exp(-std::abs(dt_s) / tau_s)));
}

Sample OutputWindow::Mean() const {
  Sample m;
  const auto mean = [&](const Sums& t) -> std::optional<Eigen::Vector3d> {
    if (t.n == 0 || t.n != n_) return std::nullopt;
    return t.first + t.sum / t.n;
  };
  m.acc_mps2 = mean(acc_);
  m.gyr_radps = mean(gyr_);
  m.mag = mean(mag_);
  return m;
}

std::optional<Eigen::Vector3d> OutputWindow::MeanVariance(int triad) const {
  const Sums& t = triad == kTriadAcc ? acc_ : triad == kTriadGyr ? gyr_ : mag_;
  if (t.n < 2 || t.n != n_) return std::nullopt;
  const Eigen::Vector3d mean = t.sum / t.n;
  const Eigen::Vector3d var =
      ((t.sum_sq - t.n * mean.cwiseProduct(mean)) / (t.n - 1)).cwiseMax(0.0);
  return var / t.n;
}

nlohmann::json VerifyWrite(const OutputWindow& before, const OutputWindow& after,
                           const StoredCalibration& replaced, const StoredCalibration& written,
                           const WriteAllowance& allowance) {
  Sample predicted = before.Mean();
  drivers::mip::ReexpressMipOutput(replaced, written, &predicted);
  const Sample measured = after.Mean();
  // The re-expression is affine: its linear part carries the before-mean's scatter.
  const auto linear = [&](int triad) {
    return drivers::mip::ReexpressLinear(replaced, written, triad == kTriadMag);
  };
  const Eigen::Matrix3d identity = Eigen::Matrix3d::Identity();
  const bool transform_changed =
      replaced.transform.value_or(identity) != written.transform.value_or(identity);
  const auto changed = [&](int triad) {
    if (transform_changed) return true;
    switch (triad) {
      case kTriadAcc:
        return !SameVector(replaced.accel_bias, written.accel_bias);
      case kTriadGyr:
        return !SameVector(replaced.gyro_bias, written.gyro_bias);
      default:
        return !SameVector(replaced.hard_iron, written.hard_iron) ||
               replaced.soft_iron.has_value() != written.soft_iron.has_value() ||
               (replaced.soft_iron && *replaced.soft_iron != *written.soft_iron);
    }
  };
  nlohmann::json triads = nlohmann::json::object();
  bool pass = true;
  double worst = 0.0;
  std::string worst_at;
  std::vector<double> all_z;  // per triad compared, its largest |z|
  for (int triad : {kTriadAcc, kTriadGyr, kTriadMag}) {
    if (!changed(triad)) continue;
    const auto& m = triad == kTriadAcc   ? measured.acc_mps2
                    : triad == kTriadGyr ? measured.gyr_radps
                                         : measured.mag;
    const auto& p = triad == kTriadAcc   ? predicted.acc_mps2
                    : triad == kTriadGyr ? predicted.gyr_radps
                                         : predicted.mag;
    const auto cb = before.MeanCovariance(triad), ca = after.MeanCovariance(triad);
    const double wander = allowance.wander_sigma[triad];
    if (!m || !p || !cb || !ca) {
      pass = false;
      triads[TriadName(triad)] = {{"error", "the device's output lacks this triad"}};
      continue;
    }
    const Eigen::Matrix3d L = linear(triad);
    const Eigen::Vector3d noise_var = (L * *cb * L.transpose() + *ca).diagonal();
    const Eigen::Vector3d sigma_noise = noise_var.cwiseSqrt();
    const Eigen::Vector3d sigma =
        (noise_var + Eigen::Vector3d::Constant(wander * wander)).cwiseSqrt();
    const Eigen::Vector3d difference = *m - *p;
    Eigen::Vector3d z;
    for (int i = 0; i < 3; ++i) {
      z[i] = sigma[i] > 0 ? difference[i] / sigma[i] : (difference[i] == 0 ? 0.0 : INFINITY);
      if (std::abs(z[i]) > worst) {
        worst = std::abs(z[i]);
        worst_at = fmt::format("{} {}", TriadName(triad), "xyz"[i]);
      }
    }
    const auto vec = [](const Eigen::Vector3d& v) { return nlohmann::json{v[0], v[1], v[2]}; };
    triads[TriadName(triad)] = {{"measured", vec(*m)},
                                {"predicted", vec(*p)},
                                {"difference", vec(difference)},
                                {"sigma", vec(sigma)},
                                {"sigma_noise", vec(sigma_noise)},
                                {"sigma_wander", wander},
                                {"z", vec(z)},
                                {"unit", TriadUnit(triad)}};
    all_z.push_back(z.cwiseAbs().maxCoeff());
  }
  const int axes = 3 * static_cast<int>(all_z.size());
  const double limit = VerifyZLimit(axes);
  for (double z : all_z) pass = pass && z <= limit;
  std::string summary =
      triads.empty()
          ? "nothing to verify: the values written are those the device held, its output does not "
            "change"
          : fmt::format(
                "{}: the uncorrected output after the write {} the prediction (largest "
                "|z| {:.2f} at {}, limit {:.2f}; {} samples before, {} after)",
                pass ? "verified" : "NOT verified", pass ? "matches" : "is off", worst, worst_at,
                limit, before.count(), after.count());
  return {{"pass", pass},
          {"z_limit", limit},
          {"samples_before", before.count()},
          {"samples_after", after.count()},
          {"seconds_between", after.MeanTimeS() - before.MeanTimeS()},
          {"triads", triads},
          {"summary", summary}};
}

bool WindowMoved(const OutputWindow& window, int triad, const std::optional<Eigen::Vector3d>& sigma,
                 double factor) {
  const auto var_mean = window.MeanVariance(triad);
  if (!sigma || !var_mean) return false;
  const Eigen::Vector3d std_dev = (*var_mean * window.count()).cwiseSqrt();
  return (std_dev.array() > factor * sigma->array()).any();
}

nlohmann::json VerifyAtPose(const MeasurementModel& model, const Eigen::VectorXd& theta,
                            const Eigen::MatrixXd& covariance, const PoseRecord& record,
                            const StoredCalibration& as_if, const StoredCalibration& in_device,
                            double wander_sigma) {
  const int triad = model.sensor() == SensorKind::kMagnetometer    ? kTriadMag
                    : model.sensor() == SensorKind::kAccelerometer ? kTriadAcc
                                                                   : kTriadGyr;
  const std::optional<TriadStats>& stats = triad == kTriadAcc   ? record.acc
                                           : triad == kTriadGyr ? record.gyr
                                                                : record.mag;
  const auto vec = [](const Eigen::Vector3d& v) { return nlohmann::json{v[0], v[1], v[2]}; };
  nlohmann::json pose = {{"phi_deg", record.pose.phi_rad * 180 / M_PI},
                         {"gamma_deg", record.pose.gamma_rad * 180 / M_PI},
                         {"psi_deg", record.pose.psi_rad * 180 / M_PI}};
  if (!stats || stats->count < 2) {
    return {{"pass", false},
            {"pose", pose},
            {"summary", "not verified: the pose's record lacks the calibrated triad"}};
  }
  // In the device's output: both re-expressed from the station's stored values into the device's.
  const auto in_device_output = [&](const Eigen::Vector3d& v) {
    Sample s;
    (triad == kTriadAcc ? s.acc_mps2 : triad == kTriadGyr ? s.gyr_radps : s.mag) = v;
    drivers::mip::ReexpressMipOutput(as_if, in_device, &s);
    return *(triad == kTriadAcc ? s.acc_mps2 : triad == kTriadGyr ? s.gyr_radps : s.mag);
  };
  const Eigen::Vector3d predicted_station = model.Predict(theta, record.pose);
  const Eigen::Vector3d measured = in_device_output(stats->mean);
  const Eigen::Vector3d predicted = in_device_output(predicted_station);
  const Eigen::Matrix3d mean_cov = stats->mean_covariance
                                       ? *stats->mean_covariance
                                       : Eigen::Matrix3d(stats->covariance / stats->count);
  // The prediction's sigma in the device's output (through the re-expression, correlations
  // included).
  Eigen::Vector3d prediction_sigma = Eigen::Vector3d::Zero();
  if (covariance.rows() == theta.size() && covariance.cols() == theta.size()) {
    prediction_sigma = PropagatedSigma(
        [&](const Eigen::VectorXd& t) { return in_device_output(model.Predict(t, record.pose)); },
        theta, covariance);
  }
  // The re-expression's linear part.
  const Eigen::Matrix3d L = drivers::mip::ReexpressLinear(as_if, in_device, triad == kTriadMag);
  const Eigen::Vector3d noise_var = (L * mean_cov * L.transpose()).diagonal();
  const Eigen::Vector3d var = noise_var + prediction_sigma.cwiseProduct(prediction_sigma) +
                              Eigen::Vector3d::Constant(wander_sigma * wander_sigma);
  const Eigen::Vector3d sigma = var.cwiseSqrt();
  const Eigen::Vector3d difference = measured - predicted;
  Eigen::Vector3d z;
  for (int i = 0; i < 3; ++i) z[i] = sigma[i] > 0 ? difference[i] / sigma[i] : INFINITY;
  const double limit = VerifyZLimit(3);
  const bool pass = z.cwiseAbs().maxCoeff() <= limit;
  Eigen::Index worst = 0;
  z.cwiseAbs().maxCoeff(&worst);
  return {{"pass", pass},
          {"pose", pose},
          {"triads",
           {{TriadName(triad),
             {{"measured", vec(measured)},
              {"predicted", vec(predicted)},
              {"difference", vec(difference)},
              {"sigma", vec(sigma)},
              {"sigma_noise", vec(noise_var.cwiseSqrt())},
              {"sigma_calibration", vec(prediction_sigma)},
              {"sigma_wander", wander_sigma},
              {"z", vec(z)},
              {"unit", TriadUnit(triad)}}}}},
          {"summary",
           fmt::format("{} at the pose (phi {:.1f} gamma {:.1f} psi {:.1f} deg): the uncorrected "
                       "output {} the calibration's prediction (largest |z| {:.2f} at {} {}, "
                       "limit {:.2f})",
                       pass ? "verified" : "NOT verified", pose["phi_deg"].get<double>(),
                       pose["gamma_deg"].get<double>(), pose["psi_deg"].get<double>(),
                       pass ? "matches" : "is off", std::abs(z[worst]), TriadName(triad),
                       "xyz"[worst], limit)}};
}

}  // namespace turncal::daemon
