#pragma once
// The manual part of `turncal COMMAND --help`: what CLI11 does not print from the options
// (description, examples, exit status, where to read more). Each command's manual sits in its
// own file beside the code that returns its exit codes, and is set where the command is added
// (tests/tools/help_test.sh checks that no command lacks one; tests/tools/exit_codes_test.py
// that the codes it documents are the codes it returns).

#include <CLI/CLI.hpp>
#include <string>

namespace turncal::tools {

struct Manual {
  // "{socket}" in the description stands for the note on where the daemon's socket is.
  const char* description;
  const char* examples;  // one command a line
  // "CODE what it means; CODE ..." (tests/tools/exit_codes_test.py reads it so).
  const char* exit_status;
  const char* see_also;
};

// The exit status every client command shares.
inline constexpr const char* kClientExitStatus =
    "0 done; 2 the daemon cannot be reached (is turncald running? --socket, $TURNCAL_SOCKET), it "
    "answered ERROR, or a command-line mistake";

// The manual as --help prints it after the options: DESCRIPTION, EXAMPLES, EXIT STATUS, SEE
// ALSO, wrapped.
std::string RenderManual(const Manual& manual);

// Sets `command`'s --help footer to its manual.
void SetManual(CLI::App* command, const Manual& manual);

}  // namespace turncal::tools
