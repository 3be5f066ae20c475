#pragma once
// The socket protocol (DESIGN.md "Socket protocol"): JSON Lines over a Unix stream socket. Each
// request has a "cmd"; each reply and event a "class".

#include <nlohmann/json.hpp>
#include <string>

namespace turncal::protocol {

inline constexpr int kProtoMajor = 1;
inline constexpr int kProtoMinor = 0;
// Longest request line the server reads; longer lines are answered with ERROR and dropped.
inline constexpr std::size_t kMaxRequestBytes = 64 * 1024;

// The greeting sent on connect: {"class":"VERSION","release":...,"proto_major":1,"proto_minor":0}.
nlohmann::json VersionMessage();

// {"class":"ERROR","message":...}.
nlohmann::json ErrorMessage(const std::string& message);

}  // namespace turncal::protocol
