#pragma once
// What the magnetometer models share: the G matrix entries g11 ... g33 (row-major) and K.

#include <Eigen/LU>
#include <cmath>
#include <string>
#include <vector>

#include "core/modeling/measurement_model.h"
#include "core/modeling/parameter_matrices.h"

namespace turncal::mag {

// Parameters g11 ... g33 with nominal G = M (the nominal mounting): a well-mounted sensor has G
// equal to the rotation from the table's frame to its axes.
inline void AppendG(const ModelContext& context, std::vector<ParameterInfo>* p) {
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      p->push_back({"g" + std::to_string(r + 1) + std::to_string(c + 1), ParameterKind::kSensor,
                    ParameterUnit::kGain, context.mounting(r, c)});
}

// Symmetric K (or K underbar) from its six upper entries k11 k12 k13 k22 k23 k33, nominal I.
inline void AppendK(std::vector<ParameterInfo>* p, ParameterKind kind) {
  for (const char* k : {"k11", "k12", "k13", "k22", "k23", "k33"}) {
    const bool diagonal = k[1] == k[2];
    p->push_back({k, kind, ParameterUnit::kGain, diagonal ? 1.0 : 0.0});
  }
}

inline void AppendVector(std::vector<ParameterInfo>* p, const char* prefix, ParameterKind kind) {
  for (const char* axis : {"x", "y", "z"}) {
    p->push_back({std::string(prefix) + axis, kind, ParameterUnit::kField, 0.0});
  }
}

// The parameter blocks' matrices (core/modeling/parameter_matrices.h).
using params::MatrixRowMajor;
using params::Symmetric;
using params::Vector;

// B_q = G^-1 (B_m - b): the field in the table's inner frame q.
inline Eigen::Vector3d CorrectWithG(const double* g, const double* b, const Eigen::Vector3d& raw) {
  return MatrixRowMajor(g).partialPivLu().solve(raw - Vector(b));
}

// The correction mag13 and mag22 share as model definitions (core/modeling/model_adapter.h):
// G^-1 (B_m - b), the field in the table's frame, with G the first nine parameters and b at
// Def::kBias (mag22's dB belongs to the table, not to the sensor).
template <class Def>
struct CorrectedWithG {
  static Eigen::Vector3d Correct(const double* theta, const Eigen::Vector3d& raw,
                                 const ModelContext&) {
    return CorrectWithG(theta, theta + Def::kBias, raw);
  }
  static OutputFrame CorrectedFrame(const ModelContext&) { return OutputFrame::kTable; }
};

inline void SetG(const Mat3<double>& G, double* theta) {
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) theta[3 * r + c] = G(r, c);
}

// G (first nine parameters), beta and b from the linear start; false when G is singular.
inline bool FromLinearG(const Mat3<double>& G, double beta, const Eigen::Vector3d& b,
                        int beta_index, int bias_index, double* theta, std::string* error) {
  if (!G.allFinite() || std::abs(G.determinant()) < 1e-12 * std::pow(G.norm(), 3)) {
    if (error) *error = "G is singular or not finite";
    return false;
  }
  SetG(G, theta);
  theta[beta_index] = beta;
  for (int i = 0; i < 3; ++i) theta[bias_index + i] = b[i];
  return true;
}

}  // namespace turncal::mag
