// turncal: the command-line tool (client and offline subcommands). Thin main over the layers.

#include <CLI/CLI.hpp>

#include "tools/capture_command.h"
#include "tools/client_commands.h"
#include "tools/decode_command.h"
#include "tools/models_command.h"
#include "tools/observability_command.h"
#include "tools/plan_compare_command.h"
#include "tools/sequence_command.h"
#include "tools/sim_command.h"
#include "tools/sim_fit_command.h"
#include "turncal/version.h"

int main(int argc, char** argv) {
  CLI::App app{"turncal — calibrate inertial sensors on a turntable (client and offline tools)",
               "turncal"};
  app.set_version_flag("--version", std::string("turncal ") + turncal::kVersion);
  app.require_subcommand(1);
  turncal::tools::AddCaptureCommands(&app);
  turncal::tools::AddDecodeCommand(&app);
  turncal::tools::AddModelsCommand(&app);
  turncal::tools::AddSimFitCommands(&app);
  turncal::tools::AddSimCommand(&app);
  turncal::tools::AddObservabilityCommands(&app);
  turncal::tools::AddPlanCompareCommand(&app);
  turncal::tools::AddSequenceCommand(&app);
  turncal::tools::AddClientCommands(&app);
  CLI11_PARSE(app, argc, argv);
  return 0;
}
