#pragma once
// `turncal registry ...` (issue 24, docs/REGISTRY.md): the calibration registry that every
// station's outbox fills (daemon/registry/registry_outbox.h), queried: a serial's history, its
// latest passing calibration, an export to CSV or JSON, the stations' last contact, the schema's
// migration, and a certificate straight from the registry.

#include <CLI/CLI.hpp>

namespace turncal::tools {

void AddRegistryCommand(CLI::App* app);

}  // namespace turncal::tools
