#pragma once
// The sequencer's words on the wire: a pose command/event as the controller sends it (and as
// captures record it), and the sequencer's events as the daemon publishes them.
//
// Pose command/event: {"event":"pose"|"cmd":"pose", "phi_deg":..., "gamma_deg":...,
// "psi_deg":..., optional "index", "dwell_s" (the dwell to collect), "hold_s" (how long the table
// holds; informational)}.
// Rate command/event (issue 21): {"cmd":"rate", "axis":"outer"|"middle"|"inner", "rate_dps":R,
// and the other two axes' angles (the rotating one's is optional), optional "index", "dwell_s"
// (at least this long, in whole revolutions)}; a capture records it as {"event":"rate",
// "rate_axis":..., "rate_dps":..., the three angles, ...}.

#include <nlohmann/json.hpp>
#include <string>

#include "core/sequencing/sequencer.h"

namespace turncal::protocol {

// True for a JSON object that is a pose command or event. False with a message when it is one
// but malformed (missing or non-finite angles, bad dwell); *is_pose says whether it was one.
bool ParsePoseCommand(const nlohmann::json& j, std::int64_t t_host_ns, Announcement* out,
                      bool* is_pose, std::string* error);

// {"class":"POSE_CAPTURED", "t":..., "index":..., "pose":{"phi_deg",...}, "collected", "needed",
//  "counts":{...}, "reason":..., "record":{...}} -- the record with each triad's mean, covariance
// and count, the window and the temperature.
nlohmann::json ToJson(const SequencerEvent& event);
// The record's move (PoseRecord::move_in) goes with its blocks unless `move_blocks` is false
// (an event's summary: protocol/move_json.h).
nlohmann::json ToJson(const PoseRecord& record, bool move_blocks = true);
// A noise profile (the state directory keeps the measured one, so a restarted station judges
// stillness exactly as before) and its inverse; the parse checks NoiseProfile::IsValid.
nlohmann::json ToJson(const NoiseProfile& profile);
bool ParseNoiseProfile(const nlohmann::json& j, NoiseProfile* out, std::string* error);
// The inverse of ToJson(PoseRecord) (journals): false with a message when a key is missing or a
// value is not a finite number of the right shape.
bool ParsePoseRecord(const nlohmann::json& j, PoseRecord* out, std::string* error);

}  // namespace turncal::protocol
