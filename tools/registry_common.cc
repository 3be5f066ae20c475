// What every `turncal registry` subcommand shares (tools/registry_common.h).

#include "tools/registry_common.h"

#include <fmt/format.h>

#include <cstdlib>
#include <filesystem>

#include "daemon/service/config.h"
#include "daemon/state/atomic_file.h"

namespace turncal::tools {

int OpenRegistry(const RegistryArgs& a, daemon::RegistryDb* db, bool migrate) {
  daemon::RegistryOptions options;
  std::string error;
  std::string config = a.config_path;
  if (a.conninfo.empty() && config.empty() && !std::getenv("TURNCAL_REGISTRY") &&
      std::filesystem::exists("/etc/turncal/turncald.toml")) {
    config = "/etc/turncal/turncald.toml";
  }
  if (!a.conninfo.empty()) {
    options.conninfo = a.conninfo;
  } else if (const char* env = std::getenv("TURNCAL_REGISTRY"); env && *env) {
    options.conninfo = env;
  } else if (!config.empty()) {
    daemon::Config c;
    if (!daemon::LoadConfig(config, &c, &error)) {
      fmt::print(stderr, "turncal registry: {}\n", error);
      return 2;
    }
    if (!c.registry.enabled()) {
      fmt::print(stderr, "turncal registry: {} has no [registry]\n", config);
      return 2;
    }
    options = c.registry;
  } else {
    fmt::print(stderr,
               "turncal registry: no registry: give --db CONNINFO, TURNCAL_REGISTRY, or --config "
               "with a [registry] section\n");
    return 2;
  }
  if (!a.password_file.empty()) options.password_file = a.password_file;
  if (!db->Connect(options, migrate, &error)) {
    fmt::print(stderr, "turncal registry: {}\n", error);
    return 2;
  }
  return 0;
}

std::string Cell(const std::optional<std::string>& v) { return v.value_or(""); }

void PrintTable(const daemon::RegistryRows& r) {
  std::vector<std::size_t> width(r.columns.size());
  for (std::size_t c = 0; c < r.columns.size(); ++c) width[c] = r.columns[c].size();
  for (const auto& row : r.rows) {
    for (std::size_t c = 0; c < row.size(); ++c) width[c] = std::max(width[c], Cell(row[c]).size());
  }
  auto line = [&](const std::vector<std::string>& cells) {
    std::string s;
    for (std::size_t c = 0; c < cells.size(); ++c) {
      s += fmt::format("{:<{}}", cells[c], c + 1 < cells.size() ? width[c] + 2 : 0);
    }
    fmt::print("{}\n", s);
  };
  line(r.columns);
  for (const auto& row : r.rows) {
    std::vector<std::string> cells;
    for (const auto& v : row) cells.push_back(Cell(v));
    line(cells);
  }
}

nlohmann::json RowsJson(const daemon::RegistryRows& r) {
  nlohmann::json list = nlohmann::json::array();
  for (const auto& row : r.rows) {
    nlohmann::json o = nlohmann::json::object();
    for (std::size_t c = 0; c < row.size(); ++c) {
      if (!row[c]) {
        o[r.columns[c]] = nullptr;
        continue;
      }
      // By the column's type: jsonb and numbers as JSON, booleans ("t"/"f"), text as strings.
      const auto kind = r.kinds[c];
      nlohmann::json parsed =
          kind == daemon::RegistryRows::Kind::kJson || kind == daemon::RegistryRows::Kind::kNumber
              ? nlohmann::json::parse(*row[c], nullptr, false)
              : nlohmann::json();
      if (kind == daemon::RegistryRows::Kind::kBoolean) {
        o[r.columns[c]] = *row[c] == "t";
      } else if (kind == daemon::RegistryRows::Kind::kJson && !parsed.is_discarded()) {
        o[r.columns[c]] = parsed;  // jsonb, null included
      } else if (!parsed.is_null() && !parsed.is_discarded()) {
        o[r.columns[c]] = parsed;
      } else {
        o[r.columns[c]] = *row[c];
      }
    }
    list.push_back(o);
  }
  return list;
}

std::optional<std::string> Maybe(const std::string& s) {
  return s.empty() ? std::nullopt : std::optional<std::string>(s);
}

int Emit(const RegistryArgs& a, const std::string& text) {
  if (a.output.empty() || a.output == "-") {
    fmt::print("{}", text);
    return 0;
  }
  std::string error;
  if (!daemon::WriteFileAtomically(a.output, text, &error)) {
    fmt::print(stderr, "turncal registry: {}\n", error);
    return 2;
  }
  fmt::print(stderr, "turncal registry: wrote {}\n", a.output);
  return 0;
}

void AddConnectionOptions(CLI::App* sub, const std::shared_ptr<RegistryArgs>& a) {
  sub->add_option("--db", a->conninfo,
                  "the registry: a libpq connection string or postgresql:// URI (else "
                  "TURNCAL_REGISTRY, else --config's [registry])");
  sub->add_option("--config", a->config_path,
                  "turncald.toml whose [registry] to use (default /etc/turncal/turncald.toml "
                  "when it exists)");
  sub->add_option("--password-file", a->password_file,
                  "the password's file (mode 600; relative: in $CREDENTIALS_DIRECTORY)");
}

}  // namespace turncal::tools
