#include "daemon/service/config_fixture.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "core/frames/mount.h"
#include "daemon/service/config_toml.h"

namespace turncal::daemon {

const FixtureSlot* Fixture::Find(const std::string& slot) const {
  for (const auto& s : slots) {
    if (s.name == slot) return &s;
  }
  return nullptr;
}

bool ParseMountNode(const toml::node& node, const char* key, const std::string& source,
                    Mat3<double>* mount, std::string* error) {
  if (const auto text = node.value<std::string>()) {
    std::string why;
    if (!ParseMountAxes(*text, mount, &why)) {
      *error = fmt::format("{}: '{}': {}", Where(node, source), key, why);
      return false;
    }
    return true;
  }
  if (const toml::array* a = node.as_array(); a && a->size() == 3) {
    double deg[3] = {0, 0, 0};
    for (std::size_t i = 0; i < 3; ++i) {
      const auto v = (*a)[i].value<double>();
      if (!v || !std::isfinite(*v) || std::abs(*v) > 360.0) {
        *error = fmt::format("{}: '{}' as angles is [x, y, z] in degrees, each within +-360",
                             Where(node, source), key);
        return false;
      }
      deg[i] = *v;
    }
    *mount = MountFromAnglesDeg(deg[0], deg[1], deg[2]);
    return true;
  }
  *error = fmt::format(
      "{}: '{}' must be the case's axes along the table's (\"+x+y+z\", \"-y+x+z\", ...) or "
      "[x, y, z] in degrees",
      Where(node, source), key);
  return false;
}

namespace {

// name and [[slot]] (`slot_key`: "slot" in a fixture file, under [fixture] too).
bool ParseSlots(const toml::table& t, const std::string& source, const std::string& context,
                Fixture* out, std::string* error) {
  if (!GetString(t, "name", &out->name, source, error)) return false;
  const toml::node* n = t.get("slot");
  if (!n) {
    *error = fmt::format("{}: {} has no [[slot]]", source, context);
    return false;
  }
  const toml::array* a = n->as_array();
  if (!a || a->empty()) {
    *error = fmt::format("{}: slots are [[slot]] tables", Where(*n, source));
    return false;
  }
  for (const toml::node& s : *a) {
    const toml::table* st = s.as_table();
    if (!st) {
      *error = fmt::format("{}: a slot is a table (name, mount)", Where(s, source));
      return false;
    }
    if (!OnlyKeys(*st, {"name", "mount"}, "a slot", source, error)) return false;
    FixtureSlot slot;
    if (!GetString(*st, "name", &slot.name, source, error)) return false;
    const toml::node* m = st->get("mount");
    if (slot.name.empty() || !m) {
      *error = fmt::format("{}: a slot needs a name and a mount", Where(s, source));
      return false;
    }
    if (!ParseMountNode(*m, "mount", source, &slot.mount, error)) return false;
    if (out->Find(slot.name)) {
      *error = fmt::format("{}: slot '{}' is named twice", Where(s, source), slot.name);
      return false;
    }
    out->slots.push_back(slot);
  }
  return true;
}

}  // namespace

bool ParseFixture(const toml::table& t, const std::string& source, Fixture* out,
                  std::string* error) {
  if (!OnlyKeys(t, {"name", "file", "slot", "batch"}, "[fixture]", source, error)) return false;
  Fixture f;
  std::string file, batch;
  if (!GetString(t, "file", &file, source, error) ||
      !GetString(t, "batch", &batch, source, error)) {
    return false;
  }
  if (file.empty()) {
    if (!ParseSlots(t, source, "[fixture]", &f, error)) return false;
    f.batch = batch;
    *out = std::move(f);
    return true;
  }
  if (t.get("slot")) {
    *error = fmt::format("{}: [fixture] has its slots in 'file' or inline, not both",
                         Where(*t.get("slot"), source));
    return false;
  }
  namespace fs = std::filesystem;
  fs::path path(file);
  if (path.is_relative()) path = fs::path(source).parent_path() / path;
  toml::table root;
  try {
    root = toml::parse_file(path.string());
  } catch (const toml::parse_error& e) {
    *error = fmt::format("{}:{}: {}", path.string(), e.source().begin.line, e.description());
    return false;
  }
  if (!OnlyKeys(root, {"name", "slot"}, "a fixture file", path.string(), error) ||
      !ParseSlots(root, path.string(), "the fixture file", &f, error)) {
    return false;
  }
  std::string name;
  if (!GetString(t, "name", &name, source, error)) return false;
  if (!name.empty()) f.name = name;  // turncald.toml's name over the file's
  f.file = path.string();
  f.batch = batch;
  *out = std::move(f);
  return true;
}

bool ParseDeviceMount(const toml::table& device, const std::string& device_name,
                      const Fixture& fixture, const std::string& source,
                      std::vector<std::string>* taken, DeviceModelOptions* own,
                      std::string* error) {
  const toml::node* slot_node = device.get("slot");
  const toml::node* mount_node = device.get("mount");
  if (slot_node && mount_node) {
    *error = fmt::format(
        "{}: device '{}' has a slot and a mount: the slot's mount is its mount (give one)",
        Where(*mount_node, source), device_name);
    return false;
  }
  if (mount_node) {
    Mat3<double> m;
    if (!ParseMountNode(*mount_node, "mount", source, &m, error)) return false;
    own->mount = m;
    return true;
  }
  if (!slot_node) return true;
  std::string slot;
  if (!GetString(device, "slot", &slot, source, error)) return false;
  const FixtureSlot* s = fixture.Find(slot);
  if (!s) {
    std::string known;
    for (const auto& k : fixture.slots) known += (known.empty() ? "" : ", ") + k.name;
    *error = fixture.slots.empty()
                 ? fmt::format("{}: device '{}' is in slot '{}' but no [fixture] is configured",
                               Where(*slot_node, source), device_name, slot)
                 : fmt::format("{}: device '{}': the fixture has no slot '{}' (its slots: {})",
                               Where(*slot_node, source), device_name, slot, known);
    return false;
  }
  if (std::find(taken->begin(), taken->end(), slot) != taken->end()) {
    *error = fmt::format("{}: device '{}': slot '{}' already holds another device",
                         Where(*slot_node, source), device_name, slot);
    return false;
  }
  taken->push_back(slot);
  own->slot = slot;
  own->mount = s->mount;
  return true;
}

}  // namespace turncal::daemon
