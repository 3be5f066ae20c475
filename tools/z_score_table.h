#pragma once
// The z-scores' verdict per parameter as the pipeline and free Monte Carlo commands print it
// (tools/pipeline_montecarlo_command.cc, tools/free_montecarlo_command.cc): mean z, std z, the
// count beyond 3 sigma where asked, and honest or not (montecarlo/z_scores.h).

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "montecarlo/z_scores.h"

namespace turncal::tools {

// One JSON object per parameter: name, mean_z, std_z, honest (and beyond_3_sigma with
// `beyond_three`).
nlohmann::json ZScoreRows(const std::vector<std::string>& parameters,
                          const montecarlo::ZScoreSummary& z, bool beyond_three);

// The same as a Markdown table: | param | mean z | std z | [beyond 3 sigma |] verdict |, a line
// per parameter; `not_honest` gets the count of parameters whose verdict is NOT HONEST.
std::string ZScoreTable(const std::vector<std::string>& parameters,
                        const montecarlo::ZScoreSummary& z, bool beyond_three, int* not_honest);

}  // namespace turncal::tools
