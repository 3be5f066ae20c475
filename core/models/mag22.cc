// mag22: the seed's magnetometer model with a platform field (eq. 21),
// B_m = G C_p^q C_NED^p B_NED + G K_ C_p^q dB + b, K_ = K^-1 symmetric.
// Parameters g11 ... g33, k11 k12 k13 k22 k23 k33, beta, dBx dBy dBz, bx by bz.
//
// Only 20 of the 22 are identifiable from turntable data (MODELS.md "The mag22 gauge"); the
// calibrator fixes the gauge, this file only states the model.

#include <Eigen/LU>

#include "core/modeling/model_adapter.h"
#include "core/models/extended.h"
#include "core/models/mag_common.h"

namespace turncal {
namespace {

struct Mag22 : mag::CorrectedWithG<Mag22> {
  static constexpr std::string_view kName = "mag22";
  static constexpr int kNumParams = 22;
  static constexpr SensorKind kSensor = SensorKind::kMagnetometer;
  static constexpr int kK = 9, kBeta = 15, kDeltaB = 16, kBias = 19;
  static constexpr int kGaugeDimension = 2;

  static std::vector<ParameterInfo> Parameters(const ModelContext& context) {
    std::vector<ParameterInfo> p;
    mag::AppendG(context, &p);
    mag::AppendK(&p, ParameterKind::kInstallation);
    p.push_back({"beta", ParameterKind::kInstallation, ParameterUnit::kAngle, 0.0});
    mag::AppendVector(&p, "dB", ParameterKind::kInstallation);
    mag::AppendVector(&p, "b", ParameterKind::kSensor);
    return p;
  }
  template <typename T>
  static Vec3<T> Predict(const T* theta, const Mat3<T>& C_p_q, const Vec3<T>& B_ned,
                         const ModelContext&) {
    const Mat3<T> G = mag::MatrixRowMajor(theta);
    return G * (C_p_q * (C_ned_p(theta[kBeta]) * B_ned)) +
           G * (mag::Symmetric(theta + kK) * (C_p_q * mag::Vector(theta + kDeltaB))) +
           mag::Vector(theta + kBias);
  }
  // Starting values: G, beta, b from the linear form (mag13's shape), K_ = I, dB = 0.
  static bool FromLinear(const Mat3<double>& G, double beta, const Eigen::Vector3d& b,
                         const ModelContext&, double* theta, std::string* error) {
    const double K_nominal[6] = {1, 0, 0, 1, 0, 1};
    for (int i = 0; i < 6; ++i) theta[kK + i] = K_nominal[i];
    for (int i = 0; i < 3; ++i) theta[kDeltaB + i] = 0.0;
    return mag::FromLinearG(G, beta, b, kBeta, kBias, theta, error);
  }
  // theta^e = (H'_1, H'_2, b), 57 entries (seed eq. 26-28).
  template <typename T>
  static void Extended(const T* theta, const ModelContext&, std::vector<T>* out) {
    const Mat3<T> G = mag::MatrixRowMajor(theta);
    extended::AppendHPrime(G, theta[kBeta], out);
    extended::AppendHPrime2<T>(G * mag::Symmetric(theta + kK), mag::Vector(theta + kDeltaB), out);
    extended::AppendVector(mag::Vector(theta + kBias), out);
  }
};

}  // namespace
}  // namespace turncal

TURNCAL_REGISTER_MODEL(mag22, turncal::Mag22)
