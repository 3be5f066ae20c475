#pragma once
// The Monte Carlo commands' test of chi^2 p-values against the uniform distribution.

#include <utility>
#include <vector>

namespace turncal::tools {

// Kolmogorov-Smirnov test of `p` against the uniform distribution on [0, 1]: the statistic D and
// its asymptotic p-value (Stephens' small-sample correction).
std::pair<double, double> KsUniform(std::vector<double> p);

}  // namespace turncal::tools
