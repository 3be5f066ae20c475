#include "montecarlo/ks_uniform.h"

#include <algorithm>
#include <cmath>

namespace turncal::montecarlo {

KsTest KsUniform(std::vector<double> p) {
  std::sort(p.begin(), p.end());
  const double n = static_cast<double>(p.size());
  double d = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    d = std::max({d, (static_cast<double>(i) + 1) / n - p[i], p[i] - static_cast<double>(i) / n});
  }
  const double lambda = (std::sqrt(n) + 0.12 + 0.11 / std::sqrt(n)) * d;
  double q = 0;
  for (int k = 1; k <= 100; ++k) {
    q += 2 * ((k % 2) ? 1.0 : -1.0) * std::exp(-2.0 * k * k * lambda * lambda);
  }
  return {d, std::clamp(q, 0.0, 1.0)};
}

}  // namespace turncal::montecarlo
