#pragma once
// The z-scores of many Monte Carlo runs, z = (estimate - truth) / sigma per parameter, and what
// they say about the reported sigma: an honest sigma gives z with mean 0 and spread 1 (and about
// 0.27 % of them beyond 3 sigma, 0.006 % beyond 4, for a normal z).

#include <Eigen/Core>
#include <string>
#include <vector>

namespace turncal::montecarlo {

// The Monte Carlo engines' verdict on a parameter (docs/ACCURACY.md): std z within
// kHonestStdZBound of 1 and mean z within kHonestMeanZBound of 0.
inline constexpr double kHonestStdZBound = 0.1, kHonestMeanZBound = 0.15;

class ZScoreSummary {
 public:
  explicit ZScoreSummary(int parameters = 0);

  // One run's z-scores, one per parameter.
  void Add(const Eigen::VectorXd& z);

  int runs() const { return runs_; }
  int parameters() const { return static_cast<int>(sum_.size()); }
  // Per parameter, over the runs added: the mean, the spread (the population standard deviation,
  // sqrt(mean z^2 - mean^2), 0 when rounding makes that negative) and the counts of |z| > 3 and
  // |z| > 4. With no run, mean and spread are NaN and 0.
  Eigen::VectorXd Mean() const;
  Eigen::VectorXd Std() const;
  const Eigen::VectorXi& BeyondThree() const { return beyond_3_; }
  const Eigen::VectorXi& BeyondFour() const { return beyond_4_; }
  // The Monte Carlo engines' verdict on a parameter (docs/ACCURACY.md): spread in [0.9, 1.1] and
  // |mean| <= 0.15.
  bool Honest(int parameter) const;
  // The correlation of the parameters' z over the runs added (the identity's entries where a
  // parameter has no spread, or with fewer than two runs).
  Eigen::MatrixXd Correlation() const;

 private:
  int runs_ = 0;
  Eigen::VectorXd sum_, sum_sq_;
  Eigen::MatrixXd sum_outer_;  // sum of z z^T
  Eigen::VectorXi beyond_3_, beyond_4_;
};

// How often a row of `runs` runs passes Honest() on every parameter when the sigma IS honest:
// z normal with mean 0, spread 1 and the given correlation between the parameters, simulated
// for `rows` rows (a fixed seed: the same answer from the same build; the normal
// draws are the standard library's). The verdict's bounds are about two
// standard errors wide at 200 runs (std z's 1/sqrt(2 * 200) = 0.05, mean z's 1/sqrt(200) =
// 0.071), so with nine parameters an honest sigma fails a row of 200 about half the time
// (docs/FREE.md, "How often an honest sigma fails a row").
double HonestRowPassChance(const Eigen::MatrixXd& correlation, int runs, int rows = 2000);

// The runs of an engine's summary (`s->runs`, each with ok, error, z and p_value) that have an
// estimate, in order: their z-scores added to `s->z`, counted in `s->solved`, and `each` called
// with each; the first error of the others in `s->first_error`. Returns their p-values.
template <typename Summary, typename Each>
std::vector<double> AddSolvedRuns(Summary* s, Each each) {
  std::vector<double> p_values;
  for (const auto& r : s->runs) {
    if (!r.ok) {
      if (s->first_error.empty()) s->first_error = r.error;
      continue;
    }
    ++s->solved;
    s->z.Add(r.z);
    p_values.push_back(r.p_value);
    each(r);
  }
  return p_values;
}

}  // namespace turncal::montecarlo
