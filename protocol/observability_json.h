#pragma once
// JSON encoding of the observability reports, the publish gate and next-pose advice (DESIGN.md
// "JSON shapes scripts rely on": `{"model":M,"params":N,"rank":r,"null_directions":[{NAME:coef}],
// ...}` for `turncal observability --json`). Angles of poses are written in degrees, sigmas in the
// parameters' own units (null when undetermined).

#include <nlohmann/json.hpp>

#include "protocol/pose_json.h"

#include "core/analysis/observability.h"
#include "core/analysis/publish_gate.h"
#include "core/planning/pose_planner.h"

namespace turncal {

// The pose as protocol/pose_json.h writes it (rate segments included).
inline nlohmann::json ToJson(const TablePose& pose) { return protocol::ToJson(pose); }

nlohmann::json ToJson(const NamedDirection& direction, const MeasurementModel& model);
nlohmann::json ToJson(const StructuralReport& report, const MeasurementModel& model);
nlohmann::json ToJson(const PoseDiversity& diversity);
nlohmann::json ToJson(const DataReport& report, const MeasurementModel& model);
nlohmann::json ToJson(const GateResult& gate);
nlohmann::json ToJson(const NextPoseAdvice& advice);

}  // namespace turncal
