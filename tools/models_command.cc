#include "tools/models_command.h"

#include <fmt/format.h>

#include <nlohmann/json.hpp>

#include "core/modeling/measurement_model.h"

namespace turncal::tools {

void AddModelsCommand(CLI::App* app) {
  auto* cmd = app->add_subcommand("models", "list the measurement models and their parameters");
  auto json = std::make_shared<bool>(false);
  cmd->add_flag("--json", *json, "one JSON object per model");
  cmd->callback([json] {
    for (const auto& name : ModelNames()) {
      std::string error;
      auto model = MakeModel(name, ModelContext{}, &error);
      if (*json) {
        nlohmann::json params = nlohmann::json::array();
        for (const auto& p : model->parameters()) {
          params.push_back({{"name", p.name},
                            {"kind", ToString(p.kind)},
                            {"unit", ToString(p.unit)},
                            {"nominal", p.nominal}});
        }
        fmt::print("{}\n",
                   nlohmann::json{
                       {"model", name}, {"sensor", ToString(model->sensor())}, {"params", params}}
                       .dump());
        continue;
      }
      fmt::print("{} ({}, {} parameters, corrected output in the {} frame)\n", name,
                 ToString(model->sensor()), model->num_parameters(),
                 ToString(model->corrected_frame()));
      for (const auto& p : model->parameters()) {
        fmt::print("  {:<8} {:<13} nominal {:<10.6g} [{}]\n", p.name, ToString(p.kind), p.nominal,
                   ToString(p.unit));
      }
    }
  });
}

}  // namespace turncal::tools
