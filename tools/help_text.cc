#include "tools/help_text.h"

namespace turncal::tools {
namespace {

constexpr const char* kSocketNote =
    "The daemon's socket is --socket, else $TURNCAL_SOCKET, else /run/turncal/turncal.sock.";

// Words of `text` in lines of at most `width` characters, each indented by two spaces.
std::string Wrap(const std::string& text, std::size_t width = 96) {
  std::string out, line;
  std::size_t start = 0;
  while (start < text.size()) {
    std::size_t end = text.find(' ', start);
    if (end == std::string::npos) end = text.size();
    const std::string word = text.substr(start, end - start);
    if (!line.empty() && line.size() + 1 + word.size() > width) {
      out += "  " + line + "\n";
      line.clear();
    }
    if (!word.empty()) line += (line.empty() ? "" : " ") + word;
    start = end + 1;
  }
  if (!line.empty()) out += "  " + line + "\n";
  return out;
}

}  // namespace

std::string RenderManual(const Manual& m) {
  std::string description = m.description;
  const std::string token = "{socket}";
  if (auto at = description.find(token); at != std::string::npos) {
    description.replace(at, token.size(), kSocketNote);
  }
  std::string examples;
  std::string line;
  for (const char* c = m.examples;; ++c) {
    if (*c == '\n' || *c == '\0') {
      examples += "  $ " + line + "\n";
      line.clear();
      if (*c == '\0') break;
    } else {
      line += *c;
    }
  }
  return "\nDESCRIPTION\n" + Wrap(description) + "\nEXAMPLES\n" + examples + "\nEXIT STATUS\n" +
         Wrap(m.exit_status) + "\nSEE ALSO\n" + Wrap(m.see_also);
}

void SetManual(CLI::App* command, const Manual& manual) { command->footer(RenderManual(manual)); }

}  // namespace turncal::tools
