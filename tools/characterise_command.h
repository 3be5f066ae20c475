#pragma once
// turncal characterise: the IEEE test report (report/characterisation.h) from calibrations, a
// state directory and rest recordings -- each item the standards ask for, measured with U (k = 2)
// or listed as not measured with what would measure it.

#include <CLI/CLI.hpp>

namespace turncal::tools {
void AddCharacteriseCommand(CLI::App* app);
}
