#include "core/frames/reference.h"

namespace turncal {

bool ReferenceVectors::IsValid(std::string* error) const {
  auto bad = [&](const char* what) {
    if (error) *error = std::string(what) + " must be finite and non-zero";
    return false;
  };
  if (!g_ned.allFinite() || g_ned.norm() < 1e-9) return bad("g_ned");
  if (!B_ned.allFinite() || B_ned.norm() < 1e-12) return bad("B_ned");
  return true;
}

}  // namespace turncal
