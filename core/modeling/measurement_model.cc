#include "core/modeling/measurement_model.h"

#include <Eigen/LU>
#include <cmath>

namespace turncal {

// One function per file of core/models/, declared and listed by the file CMake generates from
// their names (model_list.inc: TURNCAL_MODEL(stem) lines).
namespace model_registry {
#define TURNCAL_MODEL(stem) Entry Entry_##stem();
#include "turncal/model_list.inc"
#undef TURNCAL_MODEL

static const std::vector<Entry>& All() {
  static const std::vector<Entry> all = {
#define TURNCAL_MODEL(stem) Entry_##stem(),
#include "turncal/model_list.inc"
#undef TURNCAL_MODEL
  };
  return all;
}
}  // namespace model_registry

const char* ToString(SensorKind kind) {
  switch (kind) {
    case SensorKind::kAccelerometer:
      return "accelerometer";
    case SensorKind::kMagnetometer:
      return "magnetometer";
    case SensorKind::kGyroscope:
      return "gyroscope";
  }
  return "?";
}

const char* ToString(OutputFrame frame) { return frame == OutputFrame::kCase ? "case" : "table"; }

bool ModelContext::IsValid(std::string* error) const {
  if (!reference.IsValid(error)) return false;
  const bool orthonormal =
      (mounting * mounting.transpose() - Mat3<double>::Identity()).norm() < 1e-9;
  if (!mounting.allFinite() || !orthonormal || mounting.determinant() < 0) {
    if (error) *error = "mounting must be a proper rotation matrix";
    return false;
  }
  return true;
}

int MeasurementModel::index_of(std::string_view name) const {
  const auto& p = parameters();
  for (int i = 0; i < static_cast<int>(p.size()); ++i) {
    if (p[i].name == name) return i;
  }
  return -1;
}

Eigen::VectorXd MeasurementModel::nominal() const {
  const auto& p = parameters();
  Eigen::VectorXd theta(p.size());
  for (int i = 0; i < static_cast<int>(p.size()); ++i) theta[i] = p[i].nominal;
  return theta;
}

std::unique_ptr<MeasurementModel> MakeModel(std::string_view name, const ModelContext& context,
                                            std::string* error) {
  if (!context.IsValid(error)) return nullptr;
  for (const auto& entry : model_registry::All()) {
    if (entry.name == name) return entry.make(context);
  }
  if (error) {
    std::string known;
    for (const auto& n : ModelNames()) known += (known.empty() ? "" : ", ") + n;
    *error = "unknown model '" + std::string(name) + "' (known: " + known + ")";
  }
  return nullptr;
}

std::vector<std::string> ModelNames() {
  std::vector<std::string> names;
  for (const auto& entry : model_registry::All()) names.push_back(entry.name);
  return names;
}

}  // namespace turncal
