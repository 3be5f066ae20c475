// turncal: the command-line tool (client and offline subcommands). Thin main over the layers.

#include <CLI/CLI.hpp>

#include "tools/capture_command.h"
#include "tools/certificate_command.h"
#include "tools/characterise_command.h"
#include "tools/client_commands.h"
#include "tools/decode_command.h"
#include "tools/device_write_command.h"
#include "tools/free_command.h"
#include "tools/free_montecarlo_command.h"
#include "tools/models_command.h"
#include "tools/noise_command.h"
#include "tools/noise_montecarlo_command.h"
#include "tools/observability_command.h"
#include "tools/plan_compare_command.h"
#include "tools/plan_thermal_command.h"
#include "tools/registry_command.h"
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
  turncal::tools::AddNoiseCommand(&app);
  turncal::tools::AddCharacteriseCommand(&app);
  turncal::tools::AddNoiseMonteCarloCommand(&app);
  turncal::tools::AddFreeCommand(&app);
  turncal::tools::AddFreeMonteCarloCommand(&app);
  turncal::tools::AddSimCommand(&app);
  turncal::tools::AddObservabilityCommands(&app);
  turncal::tools::AddPlanCompareCommand(&app);
  turncal::tools::AddPlanThermalCommand(&app);
  turncal::tools::AddSequenceCommand(&app);
  turncal::tools::AddClientCommands(&app);
  turncal::tools::AddDeviceWriteCommand(&app);
  turncal::tools::AddCertificateCommand(&app);
  turncal::tools::AddRegistryCommand(&app);
  // Each command sets its manual (description, examples, exit status, where to read more) under
  // its --help where it is added (tools/help_text.h; tests/tools/help_test.sh checks that no
  // command lacks one).
  app.footer(
      "\nEvery command: turncal COMMAND --help shows its options, examples and exit status.\n"
      "Start with ./scripts/demo and README.md; the daemon is turncald (turncald --help).");
  try {
    app.parse(argc, argv);
  } catch (const CLI::RuntimeError& e) {
    return e.get_exit_code();  // a subcommand's own exit code
  } catch (const CLI::ParseError& e) {
    // --help and --version exit 0; every command-line mistake exits 2.
    return app.exit(e) == 0 ? 0 : 2;
  }
  return 0;
}
