#pragma once
// The live service (issue "The daemon"): one Boost.Asio event loop carries every device's bytes
// (LiveDevice: transport, dialogue on a worker thread, decoder), the Station (sequencer,
// calibrators, gate, persistence), the corrected output, and the socket server with its
// requests (docs/protocol.md). systemd: READY=1 once the socket listens and every device was
// opened or reported absent, STATUS= lines, WATCHDOG=1 from the loop, SIGHUP reloads the
// configuration (the station is rebuilt and resumes from its journal), SIGTERM/SIGINT stop
// cleanly (exit 0).

#include <boost/asio/io_context.hpp>
#include <boost/asio/signal_set.hpp>
#include <boost/asio/steady_timer.hpp>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <tuple>
#include <vector>

#include "daemon/device/live_device.h"
#include "daemon/device_write/device_writer.h"
#include "daemon/registry/registry_outbox.h"
#include "daemon/service/config.h"
#include "daemon/service/sample_stream.h"
#include "daemon/service/socket_server.h"
#include "daemon/service/solve_worker.h"
#include "daemon/station/station.h"
#include "drivers/capture/tcap.h"

namespace turncal::daemon {

struct ServiceOptions {
  std::vector<drivers::DeviceSpec> devices;
  std::map<std::string, DeviceSettings> device_settings;  // by name; defaults otherwise
  StationOptions station;                                 // state_dir set by the service
  std::string state_dir;
  SocketOptions socket;
  RegistryOptions registry;  // [registry]: the outbox's connection (none: no registry)
  std::string record_path;   // --record: a capture of every device's bytes and the pose commands
  // Re-reads the configuration on SIGHUP (nullptr: SIGHUP only logs). False with a message.
  std::function<bool(ServiceOptions*, std::string*)> reload;
};

class Service {
 public:
  explicit Service(ServiceOptions options);
  ~Service();

  // Runs until SIGTERM/SIGINT or Stop(). Returns the exit code: 0 after a clean stop, 1 when the
  // socket cannot be created or the station cannot start.
  int Run();
  void Stop();

 private:
  bool StartStation(std::string* error);
  void StartDevices();
  // Drains the solve worker, then destroys the station; clients still waiting for a pose get a
  // POSE_REJECTED saying `why` (nothing when empty).
  void DropStation(const std::string& why);
  void StopDevices();
  void OnSample(std::size_t device, const Sample& sample);
  void OnEvent(const nlohmann::json& event);
  void OnRequest(const std::shared_ptr<ClientSession>& client, const nlohmann::json& request);
  void Tick();
  void Reload();
  void UpdateStatusLine();

  nlohmann::json StatusJson() const;
  nlohmann::json DevicesJson() const;
  void HandlePose(const std::shared_ptr<ClientSession>& client, const nlohmann::json& request,
                  const nlohmann::json& id);
  void HandleReset(const std::shared_ptr<ClientSession>& client, const nlohmann::json& request,
                   const nlohmann::json& id);
  void HandlePublish(const std::shared_ptr<ClientSession>& client, const nlohmann::json& request,
                     const nlohmann::json& id);

  // device_write (docs/protocol.md "Writing a calibration into the device"): to writer_.
  void HandleDeviceWrite(const std::shared_ptr<ClientSession>& client,
                         const nlohmann::json& request, const nlohmann::json& id);
  // A device's identity after a dialogue: writer_ reconciles its record with what the device
  // holds, and gives the identity the station records.
  void OnDeviceIdentity(std::size_t device, const nlohmann::json& identity);
  // A device write's history entry (its "history" names the file) into the registry's outbox.
  void QueueDeviceWrite(const std::string& device, const nlohmann::json& entry);
  LiveDevice* DeviceNamed(const std::string& name) const;

  ServiceOptions options_;
  boost::asio::io_context io_;
  boost::asio::signal_set signals_;
  boost::asio::steady_timer tick_timer_;
  std::unique_ptr<SolveWorker> worker_;  // before station_: the station's work drains first
  std::unique_ptr<Station> station_;
  // Writes into devices: their records, a write under way, the re-expression of a written
  // device's output (daemon/device_write/device_writer.h).
  DeviceWriter writer_;
  std::vector<std::unique_ptr<LiveDevice>> devices_;
  SampleStream stream_;  // the sample lines to the clients that watch
  std::unique_ptr<SocketServer> server_;
  std::unique_ptr<drivers::CaptureWriter> recorder_;
  // The registry's outbox (daemon/registry/registry_outbox.h); null without [registry]. Shared with
  // the station's persistence, which adds to it from the solve worker.
  RegistryHandle registry_;
  std::int64_t started_ns_ = 0;
  std::int64_t last_flush_ns_ = 0;
  std::int64_t ready_deadline_ns_ = 0;
  bool ready_sent_ = false;
  std::string drop_reason_;            // why StartStation replaces a station (reload)
  std::int64_t record_start_ns_ = -1;  // time 0 of every device's records
  std::int64_t last_rate_ns_ = 0, last_watchdog_ns_ = 0, last_status_ns_ = 0;
  std::int64_t watchdog_interval_ns_ = 0;
  int next_pose_index_ = 0;
  std::string status_line_;
  bool stopping_ = false;
};

}  // namespace turncal::daemon
