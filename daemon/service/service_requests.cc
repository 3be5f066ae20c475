// The socket's requests (docs/protocol.md): status, devices, result, next_pose, pose, watch,
// reset and publish, answered on the event loop. The rest of the service -- the loop, devices,
// station, ticks and sample lines -- is in daemon/service/service.cc.
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "daemon/service/service.h"
#include "daemon/state/persistence.h"
#include "drivers/transport/transport.h"
#include "protocol/messages.h"
#include "protocol/pose_json.h"
#include "protocol/sequencer_json.h"
#include "turncal/version.h"

namespace turncal::daemon {

nlohmann::json Service::StatusJson() const {
  nlohmann::json devices = nlohmann::json::object();
  for (std::size_t i = 0; i < devices_.size(); ++i) {
    nlohmann::json d = devices_[i]->Status();
    if (station_) d["station"] = station_->Status(static_cast<int>(i));
    devices[devices_[i]->spec().name] = d;
  }
  // The batch slot by slot (issue 38), each unit with its link: a unit whose device does not
  // stream (never did, or was unplugged) waits for that first.
  nlohmann::json batch = station_ ? station_->BatchStatus() : nlohmann::json();
  if (batch.is_object()) {
    for (auto& u : batch["units"]) {
      // The device's status, as `devices` above holds it.
      if (const auto it = devices.find(u["device"].get<std::string>()); it != devices.end()) {
        const nlohmann::json& s = *it;
        const std::string link = s.value("state", "");
        const bool silent = link == "streaming" && s.value("rate_hz", 0.0) <= 0.0;
        u["link"] = silent ? "silent" : link;
        if (u["state"] == "waiting" && (link != "streaming" || silent)) {
          u["why"] =
              silent ? std::string("no samples from the device")
                     : "the device does not stream (" + link + ")" +
                           (s.value("message", "").empty() ? "" : ": " + s.value("message", ""));
        }
      }
    }
  }
  return {{"class", "STATUS"},
          {"release", kVersion},
          {"uptime_s", static_cast<double>(drivers::MonotonicNowNs() - started_ns_) / 1e9},
          {"state_dir", options_.state_dir},
          // What reached the state directory (writes, failed writes, the last failure).
          {"persistence", station_ ? station_->PersistenceStatus() : nlohmann::json()},
          {"clients", server_ ? server_->sessions().size() : 0},
          // The loop's CPU ms per captured pose (its answer, journal append and update queued),
          // and the solve worker's longest pose update (wall ms: solve, observability, gate).
          {"loop_ms",
           {{"last", station_ ? station_->capture_cpu_ms_last() : 0.0},
            {"max", station_ ? station_->capture_cpu_ms_max() : 0.0}}},
          {"solve_ms",
           {{"last", worker_ ? worker_->last_ms() : 0.0},
            {"max", worker_ ? worker_->longest_ms() : 0.0},
            {"queued", worker_ ? worker_->queued() : 0}}},
          // The registry's outbox: entries waiting, sent, the last error (null: no registry).
          {"registry", registry_.get() ? registry_.get()->Status() : nlohmann::json()},
          {"summary", status_line_},
          {"batch", batch},
          {"devices", devices}};
}

nlohmann::json Service::DevicesJson() const {
  nlohmann::json list = nlohmann::json::array();
  for (const auto& d : devices_) {
    nlohmann::json s = d->Status();
    list.push_back({{"name", s["name"]},
                    {"protocol", s["protocol"]},
                    {"port", s["port"]},
                    {"baud", s["baud"]},
                    {"state", s["state"]},
                    {"message", s["message"]},
                    {"rate_hz", s["rate_hz"]},
                    {"identity", s["identity"]}});
  }
  return {{"class", "DEVICES"}, {"devices", list}};
}

void Service::OnRequest(const std::shared_ptr<ClientSession>& client,
                        const nlohmann::json& request) {
  const nlohmann::json id = request.contains("id") ? request["id"] : nlohmann::json();
  auto reply = [&](nlohmann::json message) {
    if (!id.is_null()) message["id"] = id;
    client->Reply(message);
  };
  auto error = [&](const std::string& message) { reply(protocol::ErrorMessage(message)); };
  std::string cmd, why;
  if (!protocol::ParseCommand(request, &cmd, &why)) {
    error(why);
    return;
  }
  // Mutating commands need a peer the configuration allows.
  if (protocol::IsMutatingCommand(cmd) && !client->control()) {
    error(
        fmt::format("'{}' refused: uid {} may not change the session (control_users in the "
                    "configuration)",
                    cmd, client->uid()));
    spdlog::warn("refused '{}' from uid {} (pid {})", cmd, client->uid(), client->pid());
    return;
  }
  if (cmd == "status") {
    reply(StatusJson());
  } else if (cmd == "devices") {
    reply(DevicesJson());
  } else if (cmd == "version") {
    reply(protocol::VersionMessage());
  } else if (cmd == "result") {
    reply(station_->Result());
  } else if (cmd == "next_pose") {
    std::string device;
    bool batch = false;
    if (!protocol::ParseNextPoseRequest(request, &device, &batch, &why)) {
      error(why);
      return;
    }
    if (batch) {
      reply(station_->NextPoseBatch());
      return;
    }
    if (device.empty() && !options_.devices.empty()) device = options_.devices.front().name;
    reply(station_->NextPose(device));
  } else if (cmd == "pose" || cmd == "rate") {
    HandlePose(client, request, id);
  } else if (cmd == "watch") {
    reply(client->Watch(request));
  } else if (cmd == "reset") {
    HandleReset(client, request, id);
  } else if (cmd == "publish") {
    HandlePublish(client, request, id);
  } else if (cmd == "device_write") {
    HandleDeviceWrite(client, request, id);
  } else if (cmd == "noise") {
    std::string device, action;
    if (!protocol::ParseNoiseRequest(request, &device, &action, &why)) {
      error(why);
      return;
    }
    if (device.empty() && !options_.devices.empty()) device = options_.devices.front().name;
    nlohmann::json answer = station_->RestNoiseRequest(device, action);
    if (answer.value("class", "") == "NOISE" && action != "status") {
      spdlog::info("{}", nlohmann::json{{"class", "NOISE"},
                                        {"device", device},
                                        {"state", answer.value("state", "")},
                                        {"file", answer.value("file", "")}}
                             .dump());
    }
    reply(answer);
  } else if (cmd == "chamber") {
    std::optional<double> setpoint_c;
    if (!protocol::ParseChamberRequest(request, &setpoint_c, &why)) {
      error(why);
      return;
    }
    station_->SetChamber(setpoint_c);
    const nlohmann::json event = {
        {"class", "CHAMBER"},
        {"setpoint_c", setpoint_c ? nlohmann::json(*setpoint_c) : nlohmann::json()},
        {"soak", setpoint_c ? "announced poses wait for the sensor's temperature to settle"
                            : "no soak: poses are taken at once, at the temperature they see"}};
    spdlog::info("{}", event.dump());
    reply(event);
  }
}

void Service::HandlePose(const std::shared_ptr<ClientSession>& client,
                         const nlohmann::json& request, const nlohmann::json& id) {
  auto error = [&](const std::string& message) {
    nlohmann::json e = protocol::ErrorMessage(message);
    if (!id.is_null()) e["id"] = id;
    client->Reply(e);
  };
  Announcement a;
  std::string only, why;
  if (!protocol::ParsePoseRequest(request, drivers::MonotonicNowNs(), &a, &only, &why)) {
    error(why);
    return;
  }
  if (!request.contains("index")) a.index = next_pose_index_;
  std::vector<std::size_t> targets;
  nlohmann::json skipped = nlohmann::json::object();
  for (std::size_t i = 0; i < devices_.size(); ++i) {
    if (!only.empty() && devices_[i]->spec().name != only) continue;
    if (devices_[i]->spec().port.rfind("replay:", 0) == 0) {
      skipped[devices_[i]->spec().name] = "replays a capture: its poses come from the capture";
      continue;
    }
    if (devices_[i]->state() != "streaming") {
      skipped[devices_[i]->spec().name] = devices_[i]->state();
      continue;
    }
    targets.push_back(i);
  }
  if (!only.empty() && targets.empty() && skipped.empty()) {
    error("pose: no device '" + only + "'");
    return;
  }
  if (targets.empty()) {
    error("pose: no device is streaming (" + skipped.dump() + ")");
    return;
  }
  nlohmann::json names = nlohmann::json::array();
  std::set<std::string> waiting;
  for (std::size_t i : targets) waiting.insert(devices_[i]->spec().name);
  // Registered before announcing: POSE_STARTED comes out of the announcement itself.
  // Merged with a request for the same index still waiting (a retry on another device).
  client->pending_poses[a.index].insert(waiting.begin(), waiting.end());
  for (std::size_t i : targets) {
    if (!station_->AnnounceTo(static_cast<int>(i), a, &why)) {
      for (std::size_t j : targets) client->pending_poses[a.index].erase(devices_[j]->spec().name);
      error("pose: " + devices_[i]->spec().name + ": " + why);
      return;
    }
    names.push_back(devices_[i]->spec().name);
  }
  next_pose_index_ = std::max(next_pose_index_, a.index + 1);
  if (recorder_) {
    // The pose as a capture event, with the devices it went to (a replay announces it to those).
    nlohmann::json event = protocol::ToJson(a.pose);
    event["event"] = a.pose.is_rate() ? "rate" : "pose";
    event["index"] = a.index;
    event["devices"] = names;
    if (!a.pose.is_rate()) {
      // As the controller sent them (the replay's angles are then bit-identical to live).
      for (const char* key : {"phi_deg", "gamma_deg", "psi_deg"}) event[key] = request[key];
    }
    if (a.dwell_s) event["dwell_s"] = *a.dwell_s;
    // Recorded at the announcement's own time: the replay's sequencer then starts the pose's
    // window at the same sample as live (it takes only samples received after the command).
    devices_[targets.front()]->RecordEvent(event.dump(), a.t_host_ns);
  }
  nlohmann::json accepted = {
      {"class", "POSE_ACCEPTED"}, {"index", a.index}, {"devices", names}, {"skipped", skipped}};
  if (!id.is_null()) accepted["id"] = id;
  client->Reply(accepted);
}

void Service::HandleReset(const std::shared_ptr<ClientSession>& client,
                          const nlohmann::json& request, const nlohmann::json& id) {
  std::string note, archived, error;
  nlohmann::json reply;
  if (!protocol::ParseResetRequest(request, &note, &error)) {
    reply = protocol::ErrorMessage(error);
    if (!id.is_null()) reply["id"] = id;
    client->Reply(reply);
    return;
  }
  DropStation("the session was reset");  // closes the journal
  if (!options_.state_dir.empty() && !ArchiveSession(options_.state_dir, &archived, &error)) {
    reply = protocol::ErrorMessage("reset: " + error);
  }
  next_pose_index_ = 0;
  std::string start_error;
  if (!StartStation(&start_error)) {
    reply = protocol::ErrorMessage("reset: " + start_error);
  }
  if (reply.is_null()) {
    reply = {{"class", "RESET"},
             {"archived", archived.empty() ? nlohmann::json() : nlohmann::json(archived)},
             {"note", note},
             {"uid", client->uid()}};
    spdlog::info("session reset by uid {}{}", client->uid(),
                 archived.empty() ? "" : "; previous session archived in " + archived);
    OnEvent({{"class", "SESSION_RESET"}, {"archived", reply["archived"]}});
  }
  if (!id.is_null()) reply["id"] = id;
  client->Reply(reply);
}

void Service::HandlePublish(const std::shared_ptr<ClientSession>& client,
                            const nlohmann::json& request, const nlohmann::json& id) {
  nlohmann::json reply;
  protocol::PublishRequest p;
  std::string why;
  if (!protocol::ParsePublishRequest(request, &p, &why)) {
    reply = protocol::ErrorMessage(why);
  } else {
    const std::string& device = p.device;
    const std::string& model = p.model;
    const std::string& operator_name = p.operator_name;
    const std::string& reason = p.reason;
    const nlohmann::json who = {{"operator", operator_name},
                                {"reason", reason},
                                {"uid", client->uid()},
                                {"pid", client->pid()}};
    std::string error;
    if (!station_->PublishOverride(device, model, who, &error)) {
      reply = protocol::ErrorMessage("publish: " + error);
    } else {
      spdlog::warn("{} {} published by operator override: {} (uid {}): {}", device, model,
                   operator_name, client->uid(), reason);
      reply = {{"class", "PUBLISHED"}, {"device", device}, {"model", model}, {"override", who}};
    }
  }
  if (!id.is_null()) reply["id"] = id;
  client->Reply(reply);
}

LiveDevice* Service::DeviceNamed(const std::string& name) const {
  for (const auto& d : devices_) {
    if (d->spec().name == name) return d.get();
  }
  return nullptr;
}

void Service::HandleDeviceWrite(const std::shared_ptr<ClientSession>& client,
                                const nlohmann::json& request, const nlohmann::json& id) {
  protocol::DeviceWriteArgs args;
  std::string why;
  if (!protocol::ParseDeviceWriteRequest(request, &args, &why)) {
    nlohmann::json message = protocol::ErrorMessage(why);
    if (!id.is_null()) message["id"] = id;
    client->Reply(message);
    return;
  }
  // The answer goes to the client while it is there (a write outlives a client that went).
  DeviceWriter::Reply reply = [client = std::weak_ptr<ClientSession>(client),
                               id](nlohmann::json message) {
    const auto c = client.lock();
    if (!c) return;
    if (!id.is_null()) message["id"] = id;
    c->Reply(message);
  };
  if (!station_ && !options_.state_dir.empty()) {
    reply(protocol::ErrorMessage("device_write: no device '" + args.device + "'"));
    return;
  }
  writer_.Request(args, client->uid(), std::move(reply));
}

void Service::OnDeviceIdentity(std::size_t index, const nlohmann::json& identity) {
  const nlohmann::json station_identity =
      writer_.OnIdentity(devices_[index]->spec().name, identity);
  if (station_) station_->SetDeviceIdentity(static_cast<int>(index), station_identity);
}

void Service::QueueDeviceWrite(const std::string& device, const nlohmann::json& entry) {
  if (!registry_.get()) return;
  nlohmann::json identity = {{"serial", entry.value("serial", "")}};
  if (const LiveDevice* d = DeviceNamed(device)) {
    const nlohmann::json live = d->identity();
    if (live.is_object()) identity = live;
  }
  std::string error;
  if (!registry_.get()->AddDeviceWrite(entry, identity, entry.value("history", ""), &error)) {
    spdlog::error("{}: {}", device, error);
  }
}

}  // namespace turncal::daemon
