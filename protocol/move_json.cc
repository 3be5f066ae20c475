#include "protocol/move_json.h"

#include "protocol/json_vec3.h"
#include "protocol/pose_json.h"

namespace turncal::protocol {

nlohmann::json ToJson(const MoveRecord& m, bool with_blocks) {
  nlohmann::json j = {{"from", protocol::ToJson(m.from)},
                      {"to", protocol::ToJson(m.to)},
                      {"t_start", m.t_start_s},
                      {"t_end", m.t_end_s},
                      {"samples", m.samples},
                      {"duration_s", m.duration_s()},
                      {"blocks", m.block_s.size()},
                      {"bridged", m.bridged}};
  if (!with_blocks) return j;
  nlohmann::json increments = nlohmann::json::array(), forces = nlohmann::json::array();
  for (const auto& v : m.increment_rad) increments.push_back(JsonVec3(v));
  for (const auto& v : m.force_mps2) forces.push_back(JsonVec3(v));
  j["block_s"] = m.block_s;
  j["increment_rad"] = std::move(increments);
  j["force_mps2"] = std::move(forces);
  return j;
}

bool ParseMoveRecord(const nlohmann::json& j, MoveRecord* out, std::string* error) {
  auto fail = [&](const std::string& what) {
    if (error) *error = "move: " + what;
    return false;
  };
  if (!j.is_object()) return fail("not an object");
  MoveRecord m;
  std::string why;
  if (!ParseTablePose(j.value("from", nlohmann::json()), &m.from, &why) ||
      !ParseTablePose(j.value("to", nlohmann::json()), &m.to, &why)) {
    return fail(why);
  }
  for (const char* key : {"t_start", "t_end", "samples"}) {
    if (!j.contains(key) || !j[key].is_number()) return fail(std::string(key) + " missing");
  }
  m.t_start_s = j["t_start"].get<double>();
  m.t_end_s = j["t_end"].get<double>();
  m.samples = j["samples"].get<std::int64_t>();
  if (j.contains("bridged") && j["bridged"].is_number_integer()) {
    m.bridged = j["bridged"].get<std::int64_t>();
  }
  const auto& blocks = j.value("block_s", nlohmann::json());
  const auto& increments = j.value("increment_rad", nlohmann::json());
  const auto& forces = j.value("force_mps2", nlohmann::json::array());
  if (!blocks.is_array() || !increments.is_array() || !forces.is_array()) {
    return fail("the blocks are missing (a summary)");
  }
  for (const auto& b : blocks) {
    if (!b.is_number()) return fail("a block's seconds are not a number");
    m.block_s.push_back(b.get<double>());
  }
  for (auto* list : {&m.increment_rad, &m.force_mps2}) {
    for (const auto& v : list == &m.increment_rad ? increments : forces) {
      Eigen::Vector3d x;
      if (!ReadJsonVec3(v, &x)) return fail("a block's vector is malformed");
      list->push_back(x);
    }
  }
  if (!m.IsValid(&why)) return fail(why);
  *out = std::move(m);
  return true;
}

}  // namespace turncal::protocol
