#include "core/modeling/free_model.h"

#include <fmt/format.h>

#include <cmath>

namespace turncal {

namespace model_registry {
#define TURNCAL_FREE_MODEL(stem) FreeEntry FreeEntry_##stem();
#include "turncal/free_model_list.inc"
#undef TURNCAL_FREE_MODEL

static const std::vector<FreeEntry>& AllFree() {
  static const std::vector<FreeEntry> all = {
#define TURNCAL_FREE_MODEL(stem) FreeEntry_##stem(),
#include "turncal/free_model_list.inc"
#undef TURNCAL_FREE_MODEL
  };
  return all;
}
}  // namespace model_registry

bool FreeContext::IsValid(std::string* error) const {
  auto fail = [&](const std::string& why) {
    if (error) *error = why;
    return false;
  };
  if (!(gravity_mps2 > 0) || !std::isfinite(gravity_mps2)) {
    return fail("the gravity's magnitude must be positive");
  }
  if (!(field_magnitude >= 0) || !std::isfinite(field_magnitude)) {
    return fail("the field's magnitude must be positive, or 0 when not known");
  }
  if (!(earth_rate_radps >= 0) || !std::isfinite(earth_rate_radps)) {
    return fail("the Earth's rate must not be negative");
  }
  if (!(std::abs(latitude_deg) <= 90)) return fail("the latitude must be within +-90 degrees");
  for (double s : {acc_offset_sigma, mag_offset_sigma, gyr_offset_sigma}) {
    if (!(s >= 0) || !std::isfinite(s)) return fail("an offset sigma must not be negative");
  }
  return true;
}

Eigen::Matrix3d MeanCovariance(const TriadStats& stats, double offset_sigma) {
  Eigen::Matrix3d c = WeighedMeanCovariance(stats);
  c.diagonal().array() += offset_sigma * offset_sigma;
  return c;
}

int FreeModel::index_of(std::string_view name) const {
  const auto& p = parameters();
  for (int i = 0; i < static_cast<int>(p.size()); ++i) {
    if (p[i].name == name) return i;
  }
  return -1;
}

std::unique_ptr<FreeModel> MakeFreeModel(std::string_view name, const FreeContext& context,
                                         std::string* error) {
  if (!context.IsValid(error)) return nullptr;
  for (const auto& e : model_registry::AllFree()) {
    if (e.name == name) return e.make(context);
  }
  if (error) {
    std::string names;
    for (const auto& n : FreeModelNames()) names += (names.empty() ? "" : ", ") + n;
    *error = fmt::format("unknown free model '{}' (the free models are {})", name, names);
  }
  return nullptr;
}

std::vector<std::string> FreeModelNames() {
  std::vector<std::string> names;
  for (const auto& e : model_registry::AllFree()) names.push_back(e.name);
  return names;
}

}  // namespace turncal
