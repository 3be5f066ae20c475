// mag-physical: the traditional physical magnetometer model (seed eq. 15),
// B_m = (I+S) T_r^s C_q^r (K C_p^q C_NED^p B_NED + dB) + b, K symmetric.
// Parameters Sx Sy Sz alpha1 alpha2 alpha3 eps_x eps_y eps_z, k11 k12 k13 k22 k23 k33, beta,
// dBx dBy dBz, bx by bz. Kept for the observability demonstration: its 22 parameters reduce to
// the 13 of mag13 (dB is fixed in q, so it adds to b; K, S, alpha, eps mix into G).

#include <Eigen/LU>

#include "core/modeling/accel_physical.h"
#include "core/modeling/model_adapter.h"
#include "core/models/accel_common.h"
#include "core/models/extended.h"
#include "core/models/mag_common.h"

namespace turncal {
namespace {

struct MagPhysical {
  static constexpr std::string_view kName = "mag-physical";
  static constexpr int kNumParams = 22;
  static constexpr SensorKind kSensor = SensorKind::kMagnetometer;
  static constexpr int kS = 0, kAlpha = 3, kEps = 6, kK = 9, kBeta = 15, kDeltaB = 16, kBias = 19;

  static std::vector<ParameterInfo> Parameters(const ModelContext&) {
    std::vector<ParameterInfo> p = accel::SensorAndMountingParameters();
    mag::AppendK(&p, ParameterKind::kSensor);
    p.push_back({"beta", ParameterKind::kInstallation, ParameterUnit::kAngle, 0.0});
    mag::AppendVector(&p, "dB", ParameterKind::kInstallation);
    mag::AppendVector(&p, "b", ParameterKind::kSensor);
    return p;
  }
  template <typename T>
  static Mat3<T> SensorMatrix(const T* theta, const Mat3<double>& mounting) {
    return AccelSensorMatrix(theta + kS, theta + kAlpha) *
           C_q_r(theta[kEps], theta[kEps + 1], theta[kEps + 2], mounting);
  }
  template <typename T>
  static Vec3<T> Predict(const T* theta, const Mat3<T>& C_p_q, const Vec3<T>& B_ned,
                         const ModelContext& context) {
    const Vec3<T> field_q = mag::Symmetric(theta + kK) * (C_p_q * (C_ned_p(theta[kBeta]) * B_ned)) +
                            mag::Vector(theta + kDeltaB);
    return SensorMatrix(theta, context.mounting) * field_q + mag::Vector(theta + kBias);
  }
  // B_q = K^-1 (C_q^r^-1 ((I+S) T)^-1 (B_m - b) - dB): the Earth field in the table frame q.
  static Eigen::Vector3d Correct(const double* theta, const Eigen::Vector3d& raw,
                                 const ModelContext& context) {
    const Eigen::Vector3d field_q = SensorMatrix(theta, context.mounting)
                                        .partialPivLu()
                                        .solve(raw - mag::Vector(theta + kBias));
    return mag::Symmetric(theta + kK).partialPivLu().solve(field_q - mag::Vector(theta + kDeltaB));
  }
  static OutputFrame CorrectedFrame(const ModelContext&) { return OutputFrame::kTable; }
  // Starting values: the physical parameters from G's LQ decomposition with K = I, dB = 0.
  static bool FromLinear(const Mat3<double>& G, double beta, const Eigen::Vector3d& b,
                         const ModelContext& context, double* theta, std::string* error) {
    AccelPhysical p;
    if (!AccelPhysicalFromG(G, context.mounting, &p, error)) return false;
    const double K_nominal[6] = {1, 0, 0, 1, 0, 1};
    for (int i = 0; i < 3; ++i) {
      theta[kS + i] = p.S[i];
      theta[kAlpha + i] = p.alpha[i];
      theta[kEps + i] = p.eps[i];
      theta[kDeltaB + i] = 0.0;
      theta[kBias + i] = b[i];
    }
    for (int i = 0; i < 6; ++i) theta[kK + i] = K_nominal[i];
    theta[kBeta] = beta;
    return true;
  }
  // Seed eq. 16: H' with G = (I+S) T C_q^r K, and b' = (I+S) T C_q^r dB + b.
  template <typename T>
  static void Extended(const T* theta, const ModelContext& context, std::vector<T>* out) {
    const Mat3<T> V = SensorMatrix(theta, context.mounting);
    extended::AppendHPrime<T>(V * mag::Symmetric(theta + kK), theta[kBeta], out);
    extended::AppendVector<T>(V * mag::Vector(theta + kDeltaB) + mag::Vector(theta + kBias), out);
  }
};

}  // namespace
}  // namespace turncal

TURNCAL_REGISTER_MODEL(mag_physical, turncal::MagPhysical)
