#pragma once
// A move between two static poses (core/estimation/move_record.h) in JSON, both ways: in the
// journal with its blocks, in a POSE_CAPTURED event as a summary.
//
// {"from": {pose}, "to": {pose}, "t_start": s, "t_end": s, "samples": n, "duration_s": s,
//  "blocks": n, "block_s": [...], "increment_rad": [[x,y,z],...], "force_mps2": [[x,y,z],...]}
// The summary leaves out the last three arrays.

#include <nlohmann/json.hpp>
#include <string>

#include "core/estimation/move_record.h"

namespace turncal::protocol {

nlohmann::json ToJson(const MoveRecord& move, bool with_blocks = true);
// False with a message when a key is missing, the blocks are absent (a summary) or a value is
// not finite, or the record is not valid (MoveRecord::IsValid).
bool ParseMoveRecord(const nlohmann::json& j, MoveRecord* out, std::string* error);

}  // namespace turncal::protocol
