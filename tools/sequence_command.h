#pragma once
// `turncal sequence CAPTURE`: a capture through the decoders and the position sequencer, printing
// what the sequencer decided and why (docs/SEQUENCER.md).

#include <CLI/CLI.hpp>

namespace turncal::tools {

void AddSequenceCommand(CLI::App* app);

}  // namespace turncal::tools
