#pragma once
// Pieces of the seed's extended parameter vector theta^e (seed eq. 8, 11, 26-28), shared by the
// models' Extended() functions.

#include <vector>

#include "core/frames/rotations.h"

namespace turncal::extended {

// The rows of H' = [G cos(beta) | G sin(beta) | G], one after the other.
template <typename T>
void AppendHPrime(const Mat3<T>& G, const T& beta, std::vector<T>* out) {
  using std::cos;
  using std::sin;
  const T factor[3] = {cos(beta), sin(beta), T(1.0)};
  for (int r = 0; r < 3; ++r)
    for (const T& f : factor)
      for (int c = 0; c < 3; ++c) out->push_back(G(r, c) * f);
}

// The rows of H'_2 = [dBx W | dBy W | dBz W] with W = G K_ (seed eq. 27).
template <typename T>
void AppendHPrime2(const Mat3<T>& W, const Vec3<T>& dB, std::vector<T>* out) {
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 3; ++k)
      for (int c = 0; c < 3; ++c) out->push_back(dB[k] * W(r, c));
}

template <typename T>
void AppendVector(const Vec3<T>& v, std::vector<T>* out) {
  for (int i = 0; i < 3; ++i) out->push_back(v[i]);
}

}  // namespace turncal::extended
