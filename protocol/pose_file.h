#pragma once
// Pose lists as people write them: JSON or CSV of the table angles phi, gamma, psi in degrees.
// Used by `turncal observability --poses`, `turncal plan --poses` and (later) schedule files.
//
// JSON: an array of [phi, gamma, psi] or of objects {"phi_deg":..,"gamma_deg":..,"psi_deg":..}
// (keys "phi", "gamma", "psi" are accepted too), or an object {"poses": <such an array>}.
// CSV: one pose a line, "phi,gamma,psi" (commas, semicolons or blanks between the numbers);
// blank lines and lines starting with '#' are skipped, and a first line whose first field is not
// a number is a header.
// A rate segment (issue 21): JSON objects with "rate_axis" and "rate_dps" (protocol/pose_json.h),
// CSV lines "phi,gamma,psi,AXIS,RATE_DPS" (AXIS outer, middle or inner).

#include <string>
#include <vector>

#include "core/frames/table_pose.h"

namespace turncal {

// Parses `text`; the format is JSON when the first non-blank character is '[' or '{'. False with
// a message naming the line (CSV) or element (JSON) when anything is malformed or not finite.
bool ParsePoses(const std::string& text, std::vector<TablePose>* poses, std::string* error);

}  // namespace turncal
