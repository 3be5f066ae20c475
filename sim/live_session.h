#pragma once
// One `turncal sim --live --controller` session (sim/live.h) as a class: its steps are in
// sim/live.cc (the session's turn and the controller's side: the daemon's messages, the
// announcements) and sim/live_table.cc (the table's side: holds, unplugs, the devices' streams
// and dialogues). For those two files only.

#include <chrono>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <vector>

#include "sim/live.h"
#include "sim/live_controller.h"
#include "sim/live_pty.h"

namespace turncal::sim::live {

// One live session: the devices streaming into their ptys, the table moving through the poses
// and the lab's controller announcing them on the daemon's socket. Run() turns until the last
// pose is answered (or given up) and every sample is sent; each turn reads the daemon, moves the
// table's state on, streams what is due, announces what is due and answers the devices'
// dialogues.
class LiveSim {
 public:
  LiveSim(std::vector<LiveSimDevice>* sims, const LiveSimOptions& options, LiveSimReport* report);
  bool Run(std::string* error);

 private:
  using Clock = std::chrono::steady_clock;

  bool OpenDevices(std::string* error);
  bool CheckUnplugs(std::string* error) const;
  double SessionNow() const;  // session seconds since the start
  // The daemon's socket: (re)connect; false when no daemon answered for connect_timeout_s.
  bool KeepConnected(std::string* error);
  void ReadController(double vt);
  void OnMessage(const nlohmann::json& m, double vt);
  void CheckNoiseMeasured(const nlohmann::json& m, double vt);
  void OnAllAnswered(double vt);
  void RestAtHome(double vt);
  void HoldWhileUnanswered(double vt);
  void UnplugMidPose(double vt);
  bool Replug(double vt, std::string* error);
  bool Stream(double vt, double turn_gap_s);
  void StreamHeld(Device* d, double vt, double turn_gap_s);
  void StreamPlanned(Device* d, double vt, double turn_gap_s);
  void AnnounceWhenDue(double vt);
  nlohmann::json PoseRequest() const;
  void HoldAtEnd(bool done, double vt);
  void AnswerDialogues();
  bool LoseReply(std::size_t i, const std::uint8_t* buffer, ssize_t n, std::size_t reply_bytes);
  void DrainPtys();
  void Finish();

  void Unplug(std::size_t k, double vt);
  void BeginHold(double t0_s, double t1_s, double at_vt);
  void ShiftPastHold(double vt);
  void EndHold(double vt);
  void ForgetAnswers();  // the answers to pose p's announcement
  // The daemon's timeouts run on the wall clock whatever the speed: so does the table's wait.
  double HeldWallS(double vt) const { return (vt - hold_start_s_) / options_.speed; }

  std::vector<LiveSimDevice>* sims_;
  const LiveSimOptions& options_;
  LiveSimReport* report_;
  std::vector<Device> devices_;
  const BitErrors errors_;
  std::vector<bool> unplug_done_;
  const std::vector<SessionPoseEvent>* events_ = nullptr;
  live::Controller controller_;
  Clock::time_point start_;
  Clock::time_point last_connect_try_, disconnected_since_;
  bool ever_connected_ = false;

  std::size_t p_ = 0;       // the pose the table is at (or moving to)
  double shift_s_ = 0;      // session seconds of holds so far
  bool announced_ = false;  // pose p announced and not yet fully answered
  std::set<std::string> waiting_, rejected_by_;
  std::set<std::string> skipped_by_;     // devices the daemon left out (not streaming): again later
  int outstanding_ = 0;                  // pose requests not yet accepted or refused
  bool accepted_any_ = false;            // some device took this announcement
  std::set<std::string> retry_devices_;  // a retry goes to these only (empty: every device)
  int retries_left_;
  bool holding_ = false;
  double hold_start_s_ = 0;
  Clock::time_point retry_at_;
  // The table rests at home until the daemon has measured every device's noise (a real
  // controller waits for NOISE_MEASURED before it moves the table the first time).
  bool start_rest_ = false;
  bool start_holding_ = false;
  Clock::time_point status_at_;
  double start_s_ = 0;

  std::vector<bool> lose_left_;  // replies still to lose
  bool end_holding_ = false;     // after the last pose (hold_end_s)
  double end_hold_until_s_ = 0;
  Clock::time_point last_turn_;
  Clock::time_point due_since_ = Clock::time_point::max();  // pose p could be announced since
};

}  // namespace turncal::sim::live
