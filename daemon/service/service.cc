#include "daemon/service/service.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <boost/asio/post.hpp>
#include <charconv>
#include <chrono>
#include <cmath>
#include <csignal>
#include <thread>

#include "daemon/service/notify.h"
#include "daemon/state/persistence.h"
#include "drivers/mip/mip_stored.h"
#include "drivers/transport/transport.h"
#include "protocol/messages.h"
#include "protocol/sequencer_json.h"
#include "turncal/version.h"

namespace turncal::daemon {

namespace {

constexpr std::int64_t kNsPerMs = 1'000'000;
constexpr auto kTick = std::chrono::milliseconds(50);
}  // namespace

Service::Service(ServiceOptions options)
    : options_(std::move(options)),
      signals_(io_),
      tick_timer_(io_),
      writer_(DeviceWriter::Hooks{
          .device = [this](const std::string& name) -> WritableDevice* {
            return DeviceNamed(name);
          },
          .model_of = [this](const std::string& device,
                             const std::string& model) -> const MeasurementModel* {
            return station_ ? station_->ModelOf(device, model) : nullptr;
          },
          .noise_of = [this](const std::string& device) -> const NoiseProfile* {
            for (std::size_t i = 0; station_ && i < devices_.size(); ++i) {
              if (devices_[i]->spec().name == device) {
                return station_->NoiseOf(static_cast<int>(i));
              }
            }
            return nullptr;
          },
          .post = [this](std::function<void()> work) { boost::asio::post(io_, std::move(work)); },
          .publish = [this](const nlohmann::json& event) { OnEvent(event); },
          .history_written = [this](
                                 const std::string& device,
                                 const nlohmann::json& entry) { QueueDeviceWrite(device, entry); },
          .now_ns = [] { return drivers::MonotonicNowNs(); }}) {}

Service::~Service() {
  StopDevices();
  if (server_) server_->Stop();
  DropStation("");
}

bool Service::StartStation(std::string* error) {
  std::vector<std::string> names;
  for (const auto& d : options_.devices) names.push_back(d.name);
  StationOptions so = options_.station;
  so.state_dir = options_.state_dir;
  if (!so.IsValid(error)) return false;
  if (options_.registry.enabled() && options_.state_dir.empty()) {
    *error = "[registry] needs a state directory: the outbox lives there (--state-dir)";
    return false;
  }
  DropStation(drop_reason_);  // closes the journal before a new station opens it
  if (const auto& registry = registry_.Ensure(options_.registry, options_.state_dir)) {
    so.on_calibration_saved = [registry](const nlohmann::json& calibration) {
      std::string why;
      if (!registry->AddCalibration(calibration, &why)) spdlog::error("{}", why);
    };
  }
  writer_.Configure(options_.state_dir, options_.station);
  station_ = std::make_unique<Station>(names, so, [this](const nlohmann::json& e) { OnEvent(e); });
  if (!worker_) worker_ = std::make_unique<SolveWorker>(io_);
  station_->SetExecutor([this](std::function<void()> work, std::function<void()> done) {
    worker_->Post(std::move(work), std::move(done));
  });
  for (std::size_t i = 0; i < devices_.size(); ++i) {
    const nlohmann::json identity = devices_[i]->identity();
    if (!identity.is_null()) OnDeviceIdentity(i, identity);
  }
  // Pose indices continue after the journal's.
  for (std::size_t i = 0; i < options_.devices.size(); ++i) {
    next_pose_index_ =
        std::max(next_pose_index_, station_->Status(static_cast<int>(i))["poses"].get<int>());
  }
  return true;
}

void Service::DropStation(const std::string& why) {
  if (station_) {
    // Its queued solves would be discarded: skipped, so the drain (which holds the loop) waits
    // only for the one running and for the writes.
    station_->Abandon();
    station_->WriteDueReports();  // queued on the worker, written by the drain
  }
  if (worker_) worker_->Drain();
  if (station_ && station_->abandoned_solves() > 0) {
    spdlog::info("turncald: {} solve(s) queued for the station being replaced were skipped",
                 station_->abandoned_solves());
  }
  station_.reset();
  // Poses still being collected are never answered by the old station: say so.
  if (!server_ || why.empty()) return;
  auto sessions = server_->sessions();
  for (auto& [id, s] : sessions) {
    for (const auto& [index, devices] : s->pending_poses) {
      for (const auto& device : devices) {
        s->Reply({{"class", "POSE_REJECTED"},
                  {"device", device},
                  {"index", index},
                  {"reason", why + " while the pose was being collected; announce it again"}});
      }
    }
    s->pending_poses.clear();
  }
}

void Service::StartDevices() {
  for (std::size_t i = 0; i < options_.devices.size(); ++i) {
    const auto& spec = options_.devices[i];
    DeviceSettings settings;
    if (auto it = options_.device_settings.find(spec.name); it != options_.device_settings.end()) {
      settings = it->second;
    }
    auto device = std::make_unique<LiveDevice>(
        io_, spec, settings, [this, i](const Sample& s) { OnSample(i, s); },
        [this, name = spec.name](const std::string& level, const std::string& state,
                                 const std::string& message) {
          if (level == "error") {
            spdlog::error("{}: {}: {}", name, state, message);
          } else if (level == "warn") {
            spdlog::warn("{}: {}: {}", name, state, message);
          } else {
            spdlog::info("{}: {}: {}", name, state, message);
          }
          OnEvent({{"class", "DEVICE"}, {"device", name}, {"state", state}, {"message", message}});
        },
        [this, i](const nlohmann::json& identity) { OnDeviceIdentity(i, identity); });
    // A replayed capture's pose commands go to this device as they would from a controller.
    device->SetCaptureEventHandler([this, i](const std::string& text, std::int64_t t_host_ns) {
      const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
      Announcement a;
      bool is_pose = false;
      std::string why;
      if (j.is_discarded() || !station_) return;
      if (!protocol::ParsePoseCommand(j, t_host_ns, &a, &is_pose, &why)) {
        if (is_pose) OnEvent({{"class", "ERROR"}, {"message", "capture event: " + why}});
        return;
      }
      if (!station_->AnnounceTo(static_cast<int>(i), a, &why)) {
        OnEvent({{"class", "ERROR"}, {"message", "capture event: " + why}});
      }
      next_pose_index_ = std::max(next_pose_index_, a.index + 1);
    });
    if (recorder_) {
      device->RecordInto(recorder_.get(), static_cast<std::uint8_t>(i), record_start_ns_);
    }
    std::string error;
    if (!device->Start(&error)) {
      spdlog::error("{}: {}", spec.name, error);
      OnEvent({{"class", "ERROR"}, {"device", spec.name}, {"message", error}});
    }
    devices_.push_back(std::move(device));
  }
}

void Service::StopDevices() {
  for (auto& d : devices_) d->Stop();
  devices_.clear();
}

int Service::Run() {
  started_ns_ = drivers::MonotonicNowNs();
  std::string error;
  if (!StartStation(&error)) {
    spdlog::error("{}", error);
    return 1;
  }
  server_ = std::make_unique<SocketServer>(io_, options_.socket,
                                           [this](const std::shared_ptr<ClientSession>& c,
                                                  const nlohmann::json& r) { OnRequest(c, r); });
  if (!server_->Listen(&error)) {
    spdlog::error("{}", error);
    return 1;
  }
  if (!options_.record_path.empty()) {
    drivers::CaptureHeader header;
    for (const auto& d : options_.devices)
      header.devices.push_back({d.name, d.protocol, d.baud, {}, {}});
    header.created = "turncald " + std::string(kVersion);
    header.note = "recorded live by turncald --record";
    recorder_ = drivers::CaptureWriter::Create(options_.record_path, header, &error);
    record_start_ns_ = drivers::MonotonicNowNs();
    if (!recorder_) {
      spdlog::error("{}", error);
      return 1;
    }
  }
  spdlog::info("turncald {}: listening on {}{}", kVersion,
               options_.socket.activated_fd ? "the socket systemd passed" : options_.socket.path,
               options_.state_dir.empty() ? "" : ", state in " + options_.state_dir);
  StartDevices();
  signals_.add(SIGTERM);
  signals_.add(SIGINT);
  signals_.add(SIGHUP);
  std::function<void(const boost::system::error_code&, int)> on_signal =
      [this, &on_signal](const boost::system::error_code& ec, int signal) {
        if (ec) return;
        if (signal == SIGHUP) {
          Reload();
          signals_.async_wait(on_signal);
          return;
        }
        spdlog::info("turncald: {} received, stopping", signal == SIGTERM ? "SIGTERM" : "SIGINT");
        Stop();
      };
  signals_.async_wait(on_signal);
  if (auto w = WatchdogInterval()) {
    watchdog_interval_ns_ = std::chrono::duration_cast<std::chrono::nanoseconds>(*w).count() / 2;
  }
  ready_deadline_ns_ = drivers::MonotonicNowNs() + 5000 * kNsPerMs;
  Tick();  // READY=1 once every device's first open attempt has finished (Tick)
  io_.run();
  return 0;
}

void Service::Stop() {
  if (stopping_) return;
  stopping_ = true;
  Notify("STOPPING=1");
  tick_timer_.cancel();
  signals_.cancel();
  StopDevices();
  if (server_) server_->Stop();
  DropStation("turncald stopped");  // the journal is fsynced at every append; this closes it
  if (recorder_) {
    std::string error;
    if (!recorder_->Close(&error)) spdlog::error("recording: {}", error);
    recorder_.reset();
  }
  io_.stop();
}

void Service::Tick() {
  const std::int64_t now = drivers::MonotonicNowNs();
  if (station_) {
    for (std::size_t i = 0; i < devices_.size(); ++i) {
      if (devices_[i]->spec().port.rfind("replay:", 0) != 0) {
        station_->TickDevice(static_cast<int>(i), now);
      }
    }
  }
  writer_.Tick(now);
  if (now - last_rate_ns_ >= 1000 * kNsPerMs) {
    for (auto& d : devices_) d->UpdateRate(now);
    last_rate_ns_ = now;
  }
  if (recorder_ && now - last_flush_ns_ >= 1000 * kNsPerMs) {
    std::string error;
    recorder_->Flush(&error);  // a kill -9 loses at most a second of the recording
    last_flush_ns_ = now;
  }
  if (!ready_sent_) {
    bool all = true;
    for (const auto& d : devices_) all = all && d->attempted();
    if (all || now >= ready_deadline_ns_) {
      UpdateStatusLine();
      Notify("READY=1\nSTATUS=" + status_line_);
      spdlog::info("turncald: ready ({})", status_line_);
      ready_sent_ = true;
    }
  }
  if (watchdog_interval_ns_ > 0 && now - last_watchdog_ns_ >= watchdog_interval_ns_) {
    Notify("WATCHDOG=1");
    last_watchdog_ns_ = now;
  }
  if (now - last_status_ns_ >= 5000 * kNsPerMs) {
    const std::string before = status_line_;
    UpdateStatusLine();
    if (status_line_ != before) Notify("STATUS=" + status_line_);
    last_status_ns_ = now;
  }
  tick_timer_.expires_after(kTick);
  tick_timer_.async_wait([this](const boost::system::error_code& ec) {
    if (!ec && !stopping_) Tick();
  });
}

void Service::UpdateStatusLine() {
  int streaming = 0, poses = 0, active = 0;
  for (const auto& d : devices_) streaming += d->state() == "streaming";
  if (station_) {
    const nlohmann::json r = station_->Result();
    for (const auto& [name, d] : r["devices"].items()) {
      poses += d["poses"].get<int>();
      for (const auto& [model, m] : d["models"].items())
        active += m["active_version"].get<int>() > 0;
    }
  }
  status_line_ = fmt::format("{}/{} devices streaming, {} poses captured, {} calibrations active",
                             streaming, devices_.size(), poses, active);
}

void Service::Reload() {
  Notify("RELOADING=1");
  if (!options_.reload) {
    spdlog::warn("turncald: SIGHUP: no configuration file to reload");
    Notify("READY=1");
    return;
  }
  ServiceOptions next = options_;
  std::string error;
  if (!options_.reload(&next, &error)) {
    spdlog::error("turncald: SIGHUP: the configuration is not reloaded: {}", error);
    OnEvent({{"class", "ERROR"}, {"message", "reload refused: " + error}});
    Notify("READY=1");
    return;
  }
  // Devices and station are rebuilt; the station resumes from its journal, so every captured
  // pose is kept (a pose being collected is lost and must be announced again).
  StopDevices();
  if (next.socket.path != options_.socket.path || next.socket.group != options_.socket.group) {
    spdlog::warn("turncald: SIGHUP: socket and socket_group take effect at the next start");
  }
  server_->SetControlUids(next.socket.control_uids);  // control_users: from now on
  next.socket.path = options_.socket.path;
  next.socket.group = options_.socket.group;
  next.socket.activated_fd = options_.socket.activated_fd;
  next.reload = options_.reload;
  options_ = std::move(next);
  drop_reason_ = "the configuration was reloaded";
  if (!StartStation(&error)) {
    spdlog::error("turncald: SIGHUP: {}", error);
  }
  drop_reason_.clear();
  StartDevices();
  spdlog::info("turncald: configuration reloaded ({} devices)", devices_.size());
  OnEvent({{"class", "RELOADED"}, {"devices", options_.devices.size()}});
  UpdateStatusLine();
  Notify("READY=1\nSTATUS=" + status_line_);
}

void Service::OnSample(std::size_t device, const Sample& sample) {
  // After a write into the device, the station sees its output in the stored values its
  // calibrations were made with; `raw` shows what the device sends.
  Sample reexpressed;
  const Sample* station_sample = &writer_.OnSample(sample, &reexpressed);
  if (!station_) return;
  station_->OnSample(static_cast<int>(device), *station_sample);
  if (server_->sessions().empty()) return;
  stream_.Send(*server_, *station_, static_cast<int>(device), sample, *station_sample);
}

void Service::OnEvent(const nlohmann::json& event) {
  const std::string kind = event.value("class", "");
  if (kind == "POSE_CAPTURED") writer_.OnPoseCaptured(event);
  if (kind == "POSE_CAPTURED" || kind == "POSE_REJECTED" || kind == "CALIBRATION_ACTIVE" ||
      kind == "NOISE_MEASURED" || kind == "NOISE_RETRY" || kind == "SESSION_RESUMED" ||
      (kind == "ERROR" && event.contains("device"))) {
    nlohmann::json brief = event;
    brief.erase("record");
    spdlog::info("{}", brief.dump());
  }
  if (kind == "ESTIMATE") {
    spdlog::info("{} {}: {} poses, gate {}", event.value("device", ""), event.value("model", ""),
                 event.value("poses", 0), event["gate"].value("pass", false) ? "pass" : "fail");
  }
  if (server_) server_->Publish(event);
}

}  // namespace turncal::daemon
