#include "daemon/service/config_toml.h"

#include <fmt/format.h>

#include <cmath>

namespace turncal::daemon {

std::string Where(const toml::node& node, const std::string& source) {
  const auto& r = node.source();
  return fmt::format("{}:{}", source, r.begin.line);
}

// Checks that `table` has only `allowed` keys.
bool OnlyKeys(const toml::table& table, const std::set<std::string>& allowed,
              const std::string& context, const std::string& source, std::string* error) {
  for (const auto& [key, node] : table) {
    if (!allowed.count(std::string(key.str()))) {
      std::string list;
      for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
      *error = fmt::format("{}: unknown key '{}' in {} (known: {})", Where(node, source), key.str(),
                           context, list);
      return false;
    }
  }
  return true;
}

bool GetNumber(const toml::table& t, const char* key, double* out, const std::string& source,
               std::string* error) {
  const toml::node* n = t.get(key);
  if (!n) return true;
  if (auto v = n->value<double>()) {
    if (!std::isfinite(*v)) {
      *error = fmt::format("{}: '{}' must be finite", Where(*n, source), key);
      return false;
    }
    *out = *v;
    return true;
  }
  *error = fmt::format("{}: '{}' must be a number", Where(*n, source), key);
  return false;
}

bool GetString(const toml::table& t, const char* key, std::string* out, const std::string& source,
               std::string* error) {
  const toml::node* n = t.get(key);
  if (!n) return true;
  if (auto v = n->value<std::string>()) {
    *out = *v;
    return true;
  }
  *error = fmt::format("{}: '{}' must be a string", Where(*n, source), key);
  return false;
}

bool GetVector(const toml::table& t, const char* key, Eigen::Vector3d* out,
               const std::string& source, std::string* error) {
  const toml::node* n = t.get(key);
  if (!n) return true;
  const toml::array* a = n->as_array();
  bool ok = a && a->size() == 3;
  for (std::size_t i = 0; ok && i < 3; ++i) {
    auto v = (*a)[i].value<double>();
    ok = v && std::isfinite(*v);
    if (ok) (*out)[static_cast<Eigen::Index>(i)] = *v;
  }
  if (!ok)
    *error = fmt::format("{}: '{}' must be [x, y, z] (finite numbers)", Where(*n, source), key);
  return ok;
}

// A list of finite numbers (possibly empty).
bool GetNumberList(const toml::table& t, const char* key, std::vector<double>* out,
                   const std::string& source, std::string* error) {
  const toml::node* n = t.get(key);
  if (!n) return true;
  const toml::array* a = n->as_array();
  std::vector<double> values;
  bool ok = a != nullptr;
  for (std::size_t i = 0; ok && i < a->size(); ++i) {
    auto v = (*a)[i].value<double>();
    ok = v && std::isfinite(*v);
    if (ok) values.push_back(*v);
  }
  if (!ok) {
    *error = fmt::format("{}: '{}' must be a list of finite numbers", Where(*n, source), key);
    return false;
  }
  *out = values;
  return true;
}

// A whole number in [0, 1000].
bool GetInt(const toml::table& t, const char* key, int* out, const std::string& source,
            std::string* error) {
  const toml::node* n = t.get(key);
  if (!n) return true;
  const auto* i = n->as_integer();
  if (!i || i->get() < 0 || i->get() > 1000) {
    *error = fmt::format("{}: '{}' must be a whole number from 0 to 1000", Where(*n, source), key);
    return false;
  }
  *out = static_cast<int>(i->get());
  return true;
}

// One number for all three table axes, or [inner, middle, outer].
bool GetAxes(const toml::table& t, const char* key, Eigen::Vector3d* out, const std::string& source,
             std::string* error) {
  const toml::node* n = t.get(key);
  if (!n) return true;
  if (n->as_array()) return GetVector(t, key, out, source, error);
  double v = 0;
  if (!GetNumber(t, key, &v, source, error)) return false;
  out->setConstant(v);
  return true;
}

bool GetModels(const toml::table& t, std::vector<std::string>* models, const std::string& source,
               std::string* error) {
  const toml::node* n = t.get("models");
  if (!n) return true;
  const toml::array* a = n->as_array();
  if (!a || a->empty()) {
    *error =
        fmt::format("{}: 'models' must be a non-empty array of model names", Where(*n, source));
    return false;
  }
  models->clear();
  for (const auto& m : *a) {
    auto v = m.value<std::string>();
    if (!v) {
      *error = fmt::format("{}: 'models' must hold strings", Where(m, source));
      return false;
    }
    models->push_back(*v);
  }
  return true;
}

}  // namespace turncal::daemon
