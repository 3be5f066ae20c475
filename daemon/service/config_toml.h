#pragma once
// Reading turncald.toml's values (daemon/service/config.cc): each getter leaves the value as it
// is when the key is absent and fails with a message naming the file, line and key when it has
// the wrong type; every refusal says where.

#include <toml++/toml.h>
#include <Eigen/Core>
#include <set>
#include <string>
#include <vector>

namespace turncal::daemon {

std::string Where(const toml::node& node, const std::string& source);
// Checks that `table` has only `allowed` keys.
bool OnlyKeys(const toml::table& table, const std::set<std::string>& allowed,
              const std::string& context, const std::string& source, std::string* error);
bool GetNumber(const toml::table& t, const char* key, double* out, const std::string& source,
               std::string* error);
bool GetString(const toml::table& t, const char* key, std::string* out, const std::string& source,
               std::string* error);
bool GetVector(const toml::table& t, const char* key, Eigen::Vector3d* out,
               const std::string& source, std::string* error);
// A list of finite numbers (possibly empty).
bool GetNumberList(const toml::table& t, const char* key, std::vector<double>* out,
                   const std::string& source, std::string* error);
// A whole number in [0, 1000].
bool GetInt(const toml::table& t, const char* key, int* out, const std::string& source,
            std::string* error);
// One number for all three table axes, or [inner, middle, outer].
bool GetAxes(const toml::table& t, const char* key, Eigen::Vector3d* out, const std::string& source,
             std::string* error);
bool GetModels(const toml::table& t, std::vector<std::string>* models, const std::string& source,
               std::string* error);

}  // namespace turncal::daemon
