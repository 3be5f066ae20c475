#include "tools/z_score_table.h"

#include <fmt/format.h>

namespace turncal::tools {

nlohmann::json ZScoreRows(const std::vector<std::string>& parameters,
                          const montecarlo::ZScoreSummary& z, bool beyond_three) {
  const Eigen::VectorXd mean = z.Mean(), std_z = z.Std();
  nlohmann::json rows = nlohmann::json::array();
  for (std::size_t i = 0; i < parameters.size(); ++i) {
    const auto k = static_cast<Eigen::Index>(i);
    nlohmann::json row = {{"name", parameters[i]},
                          {"mean_z", mean[k]},
                          {"std_z", std_z[k]},
                          {"honest", z.Honest(static_cast<int>(i))}};
    if (beyond_three) row["beyond_3_sigma"] = z.BeyondThree()[k];
    rows.push_back(row);
  }
  return rows;
}

std::string ZScoreTable(const std::vector<std::string>& parameters,
                        const montecarlo::ZScoreSummary& z, bool beyond_three, int* not_honest) {
  const Eigen::VectorXd mean = z.Mean(), std_z = z.Std();
  *not_honest = 0;
  std::string table = beyond_three ? "| param | mean z | std z | beyond 3 sigma | verdict |\n"
                                     "|---|---|---|---|---|\n"
                                   : "| param | mean z | std z | verdict |\n|---|---|---|---|\n";
  for (std::size_t i = 0; i < parameters.size(); ++i) {
    const auto k = static_cast<Eigen::Index>(i);
    const bool honest = z.Honest(static_cast<int>(i));
    *not_honest += !honest;
    const std::string beyond =
        beyond_three ? fmt::format(" {} |", z.BeyondThree()[k]) : std::string();
    table += fmt::format("| {} | {:+.3f} | {:.3f} |{} {} |\n", parameters[i], mean[k], std_z[k],
                         beyond, honest ? "ok" : "NOT HONEST");
  }
  return table;
}

}  // namespace turncal::tools
