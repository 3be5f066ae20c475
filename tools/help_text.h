#pragma once
// The manual part of `turncal COMMAND --help`: what CLI11 does not print from the options
// (description, examples, exit status, where to read more), kept in one place so every
// subcommand has one and a test can check that none is missing.

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

namespace turncal::tools {

// Sets the footer of every subcommand of `app` that has a manual entry; returns the names of
// subcommands without one (a test expects none).
std::vector<std::string> AddManualFooters(CLI::App* app);

// The manual text of one subcommand ("" when there is none).
std::string ManualFooter(const std::string& subcommand);

}  // namespace turncal::tools
