#include "tools/models_command.h"

#include <fmt/format.h>

#include <nlohmann/json.hpp>

#include "core/modeling/free_model.h"
#include "core/modeling/measurement_model.h"
#include "tools/help_text.h"

namespace turncal::tools {
namespace {

constexpr Manual kModelsManual = {
    "Lists every model and its parameters in the order results use: first the turntable models "
    "(marked \"turntable\": they need the table's known poses, turncald's pose source and "
    "replays), then the free models (marked \"free, no turntable\": a tumble with unknown "
    "angles, turncal free and turncald's free pose source).",
    "turncal models\nturncal models --json", "0; 2 a command-line mistake", "docs/models.md"};

nlohmann::json ParametersJson(const std::vector<ParameterInfo>& parameters) {
  nlohmann::json params = nlohmann::json::array();
  for (const auto& p : parameters) {
    params.push_back({{"name", p.name},
                      {"kind", ToString(p.kind)},
                      {"unit", ToString(p.unit)},
                      {"nominal", p.nominal}});
  }
  return params;
}

void PrintParameters(const std::vector<ParameterInfo>& parameters) {
  for (const auto& p : parameters) {
    fmt::print("  {:<8} {:<13} nominal {:<10.6g} [{}]\n", p.name, ToString(p.kind), p.nominal,
               ToString(p.unit));
  }
}

// The models of a calibration on a turntable (core/models/, MakeModel).
void ListTurntableModels(bool json) {
  for (const auto& name : ModelNames()) {
    std::string error;
    auto model = MakeModel(name, ModelContext{}, &error);
    if (json) {
      fmt::print("{}\n", nlohmann::json{{"model", name},
                                        {"sensor", ToString(model->sensor())},
                                        {"turntable", true},
                                        {"params", ParametersJson(model->parameters())}}
                             .dump());
      continue;
    }
    fmt::print("{} ({}, {} parameters, corrected output in the {} frame; turntable)\n", name,
               ToString(model->sensor()), model->num_parameters(),
               ToString(model->corrected_frame()));
    PrintParameters(model->parameters());
  }
}

// The models of a calibration without a turntable (core/modeling/free_model.h, docs/FREE.md).
void ListFreeModels(bool json) {
  for (const auto& name : FreeModelNames()) {
    std::string error;
    auto model = MakeFreeModel(name, FreeContext{}, &error);
    if (json) {
      fmt::print("{}\n", nlohmann::json{{"model", name},
                                        {"sensor", ToString(model->sensor())},
                                        {"turntable", false},
                                        {"description", model->description()},
                                        {"params", ParametersJson(model->parameters())}}
                             .dump());
      continue;
    }
    fmt::print("{} ({}, {} parameters; free, no turntable): {}\n", name, ToString(model->sensor()),
               model->num_parameters(), model->description());
    PrintParameters(model->parameters());
  }
}

}  // namespace

void AddModelsCommand(CLI::App* app) {
  auto* cmd = app->add_subcommand(
      "models", "list the measurement models (turntable and free) and their parameters");
  SetManual(cmd, kModelsManual);
  auto json = std::make_shared<bool>(false);
  cmd->add_flag("--json", *json, "one JSON object per model");
  cmd->callback([json] {
    ListTurntableModels(*json);
    ListFreeModels(*json);
  });
}

}  // namespace turncal::tools
