// mag13: the seed's magnetometer model (eq. 16-17), B_m = G C_p^q C_NED^p B_NED + b'.
// Parameters g11 ... g33, beta, bx by bz.

#include <Eigen/LU>

#include "core/modeling/model_adapter.h"
#include "core/models/extended.h"
#include "core/models/mag_common.h"

namespace turncal {
namespace {

struct Mag13 : mag::CorrectedWithG<Mag13> {
  static constexpr std::string_view kName = "mag13";
  static constexpr int kNumParams = 13;
  static constexpr SensorKind kSensor = SensorKind::kMagnetometer;
  static constexpr int kBeta = 9;
  static constexpr int kBias = 10;

  static std::vector<ParameterInfo> Parameters(const ModelContext& context) {
    std::vector<ParameterInfo> p;
    mag::AppendG(context, &p);
    p.push_back({"beta", ParameterKind::kInstallation, ParameterUnit::kAngle, 0.0});
    mag::AppendVector(&p, "b", ParameterKind::kSensor);
    return p;
  }
  template <typename T>
  static Vec3<T> Predict(const T* theta, const Mat3<T>& C_p_q, const Vec3<T>& B_ned,
                         const ModelContext&) {
    return mag::MatrixRowMajor(theta) * (C_p_q * (C_ned_p(theta[kBeta]) * B_ned)) +
           mag::Vector(theta + kBias);
  }
  static bool FromLinear(const Mat3<double>& G, double beta, const Eigen::Vector3d& b,
                         const ModelContext&, double* theta, std::string* error) {
    return mag::FromLinearG(G, beta, b, kBeta, kBias, theta, error);
  }
  template <typename T>
  static void Extended(const T* theta, const ModelContext&, std::vector<T>* out) {
    extended::AppendHPrime(mag::MatrixRowMajor(theta), theta[kBeta], out);
    extended::AppendVector(mag::Vector(theta + kBias), out);
  }
};

}  // namespace
}  // namespace turncal

TURNCAL_REGISTER_MODEL(mag13, turncal::Mag13)
