#pragma once
// A table pose on the wire: {"phi_deg", "gamma_deg", "psi_deg"} and, for a rate segment (issue
// 21), "rate_axis" ("outer" | "middle" | "inner") and "rate_dps" -- the rotating axis's angle is
// then not meaningful (written as given, 0 when the controller omitted it).

#include <nlohmann/json.hpp>
#include <string>

#include "core/frames/table_pose.h"

namespace turncal::protocol {

nlohmann::json ToJson(const TablePose& pose);

// The inverse: false with a message when an angle is missing or not a finite number, or the rate
// keys are malformed. With `rotating_angle_optional`, a rate segment's rotating axis may lack
// its angle (a controller's command: it is 0 then).
bool ParseTablePose(const nlohmann::json& j, TablePose* out, std::string* error,
                    bool rotating_angle_optional = false);

}  // namespace turncal::protocol
