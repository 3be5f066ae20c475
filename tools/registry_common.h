#pragma once
// What every `turncal registry` subcommand shares (tools/registry_command.h): the arguments, the
// connection (--db, TURNCAL_REGISTRY or turncald.toml's [registry]), and rows printed as a table,
// as JSON, or written to a file.

#include <CLI/CLI.hpp>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "daemon/registry/registry_db.h"

namespace turncal::tools {

struct RegistryArgs {
  std::string conninfo;       // --db
  std::string config_path;    // --config: turncald.toml's [registry]
  std::string password_file;  // --password-file
  std::string serial, model, station, format = "text", output, pdf, issued;
  int version = 0;
  bool json = false;
  bool passing_only = false;
};

// The connection: --db, else TURNCAL_REGISTRY, else --config's (or /etc/turncal/turncald.toml's)
// [registry]. 0, or exit code 2 with a message printed when none works.
int OpenRegistry(const RegistryArgs& a, daemon::RegistryDb* db, bool migrate = false);
// --db, --config and --password-file on a subcommand.
void AddConnectionOptions(CLI::App* sub, const std::shared_ptr<RegistryArgs>& a);
// A cell's text ("" for NULL).
std::string Cell(const std::optional<std::string>& v);
// A table of rows for people: columns padded to their widest cell.
void PrintTable(const daemon::RegistryRows& r);
// Rows as JSON objects: jsonb and numbers as JSON, booleans as booleans, text as strings.
nlohmann::json RowsJson(const daemon::RegistryRows& r);
// "" as SQL NULL.
std::optional<std::string> Maybe(const std::string& s);
// `text` to stdout, or atomically to a.output (0; 2 with a message when it cannot be written).
int Emit(const RegistryArgs& a, const std::string& text);

// `turncal registry yield` and `turncal registry batch ID` (tools/registry_batches.cc).
void AddRegistryBatchCommands(CLI::App* registry);
// `turncal registry drift SERIAL` (tools/registry_drift.cc).
void AddRegistryDriftCommand(CLI::App* registry);
// Its analysis: one row per model and parameter of `serial`'s passing calibrations (one a
// session), as `turncal registry drift --json` prints them; only `model` when not empty; `text`
// (may be null) gets the table. False with a message when the query fails; an empty list when
// the serial has none.
bool AnalyseSerialDrift(daemon::RegistryDb* db, const std::string& serial, const std::string& model,
                        const std::map<std::string, double>& override_tolerance,
                        nlohmann::json* rows, std::string* text, std::string* error);

}  // namespace turncal::tools
