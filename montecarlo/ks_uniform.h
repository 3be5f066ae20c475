#pragma once
// The Monte Carlo engines' test of chi^2 p-values against the uniform distribution: when the
// noise model is right, the fit check's p-values over many sessions are uniform on [0, 1].

#include <vector>

namespace turncal::montecarlo {

struct KsTest {
  double d = 0.0;  // the largest distance between the empirical and the uniform distribution
  double p = 1.0;  // the probability of a D at least this large from a uniform sample
};

// Kolmogorov-Smirnov test of `p` (at least one value) against the uniform distribution on
// [0, 1]: the statistic D = max_i max(i/n - p_(i), p_(i) - (i-1)/n) over the sorted sample and
// its asymptotic p-value Q_KS(lambda) = 2 sum_k (-1)^(k-1) exp(-2 k^2 lambda^2) with Stephens'
// small-sample correction lambda = (sqrt(n) + 0.12 + 0.11 / sqrt(n)) D (Numerical Recipes,
// 3rd ed., 14.3.3), clamped to [0, 1].
KsTest KsUniform(std::vector<double> p);

}  // namespace turncal::montecarlo
