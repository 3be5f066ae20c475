#include "sim/live.h"

#include <fmt/format.h>

#include <chrono>

#include "core/frames/units.h"
#include "protocol/pose_json.h"
#include "sim/live_session.h"

namespace turncal::sim {

namespace live {

LiveSim::LiveSim(std::vector<LiveSimDevice>* sims, const LiveSimOptions& options,
                 LiveSimReport* report)
    : sims_(sims),
      options_(options),
      report_(report),
      errors_(options.bit_error_rate),
      controller_(options.controller),
      retries_left_(options.retries),
      lose_left_(options.lose_replies.size(), true) {}

bool LiveSim::OpenDevices(std::string* error) {
  devices_ = std::vector<Device>(sims_->size());
  for (std::size_t i = 0; i < sims_->size(); ++i) {
    Device& d = devices_[i];
    d.path = (*sims_)[i].path;
    d.capture = &(*sims_)[i].capture;
    d.protocol = d.capture->header.devices.at(0).protocol;
    d.period_s = 1.0 / d.capture->session_options.rate_hz;
    d.speed = options_.speed;
    d.emulator = live::PowerUp(d, i, options_);
    if (!d.emulator->storage_error().empty()) {
      Say({{"event", "device_storage"},
           {"device", d.path},
           {"error", d.emulator->storage_error()}});
    }
    if (!live::OpenDevice(&d, error)) return false;
  }
  for (std::size_t i = 0; i < devices_.size(); ++i) {
    errors_.Start(&devices_[i], options_.fault_seed, i);
  }
  return true;
}

bool LiveSim::CheckUnplugs(std::string* error) const {
  for (const auto& u : options_.unplugs) {
    if (u.device < 0 || static_cast<std::size_t>(u.device) >= devices_.size()) {
      *error =
          fmt::format("unplug: there is no device {} (0 to {})", u.device, devices_.size() - 1);
      return false;
    }
  }
  return true;
}

double LiveSim::SessionNow() const {
  return std::chrono::duration<double>(Clock::now() - start_).count() * options_.speed;
}

bool LiveSim::Run(std::string* error) {
  *report_ = LiveSimReport{};
  if (sims_->empty() || options_.controller.empty()) {
    *error = "the live controller needs at least one device and the daemon's socket";
    return false;
  }
  if (!OpenDevices(error) || !CheckUnplugs(error)) return false;
  unplug_done_.assign(options_.unplugs.size(), false);
  events_ = &devices_[0].capture->session.events;
  report_->poses = static_cast<int>(events_->size());
  report_->frames_sent.assign(devices_.size(), 0);
  report_->frames_withheld.assign(devices_.size(), 0);
  report_->frames_dropped.assign(devices_.size(), 0);
  start_ = Clock::now();
  last_connect_try_ = start_ - std::chrono::seconds(1);
  disconnected_since_ = start_;
  retry_at_ = start_;
  start_rest_ = !events_->empty();
  status_at_ = start_;
  start_s_ = devices_[0].capture->session_options.start_s;
  last_turn_ = Clock::now();
  for (;;) {
    const double vt = SessionNow();
    const double turn_gap_s = std::chrono::duration<double>(Clock::now() - last_turn_).count();
    last_turn_ = Clock::now();
    if (!KeepConnected(error)) return false;
    if (controller_.connected()) ReadController(vt);
    RestAtHome(vt);
    HoldWhileUnanswered(vt);
    UnplugMidPose(vt);
    if (!Replug(vt, error)) return false;
    const bool done = Stream(vt, turn_gap_s);
    AnnounceWhenDue(vt);
    HoldAtEnd(done, vt);
    if (done && (!end_holding_ || vt >= end_hold_until_s_)) break;
    AnswerDialogues();
  }
  DrainPtys();
  Finish();
  return true;
}

bool LiveSim::KeepConnected(std::string* error) {
  if (controller_.connected() ||
      Clock::now() - last_connect_try_ <= std::chrono::milliseconds(200)) {
    return true;
  }
  last_connect_try_ = Clock::now();
  if (controller_.TryConnect()) {
    if (ever_connected_) ++report_->reconnects;
    ever_connected_ = true;
    Say({{"event", "controller"}, {"state", "connected"}, {"socket", options_.controller}});
  } else if (std::chrono::duration<double>(Clock::now() - disconnected_since_).count() >
             options_.connect_timeout_s) {
    *error = fmt::format("no turncald answered on {} for {} s", options_.controller,
                         options_.connect_timeout_s);
    return false;
  }
  return true;
}

void LiveSim::ReadController(double vt) {
  std::vector<nlohmann::json> messages;
  if (!controller_.Read(&messages)) {
    Say({{"event", "controller"}, {"state", "disconnected"}});
    disconnected_since_ = Clock::now();
    announced_ = false;  // announced again once the daemon is back
    ForgetAnswers();
  }
  for (const auto& m : messages) OnMessage(m, vt);
}

void LiveSim::CheckNoiseMeasured(const nlohmann::json& m, double vt) {
  if (!(start_rest_ && m.contains("devices") && m["devices"].is_object() &&
        !m["devices"].empty())) {
    return;
  }
  bool measured = true;
  for (const auto& [name, dev] : m["devices"].items()) {
    measured = measured && dev.contains("station") && dev["station"].is_object() &&
               dev["station"].value("noise", "") == "measured";
  }
  if (measured) {
    start_rest_ = false;
    Say({{"event", "start_rest"}, {"state", "noise measured"}, {"after_s", vt}});
  }
}

void LiveSim::OnMessage(const nlohmann::json& m, double vt) {
  const std::string kind = m.value("class", "");
  if (kind == "STATUS") CheckNoiseMeasured(m, vt);
  const bool ours = announced_ && m.value("index", -1) == static_cast<int>(p_);
  if (kind == "POSE_ACCEPTED" && ours) {
    --outstanding_;
    accepted_any_ = true;
    for (const auto& name : m["devices"]) waiting_.insert(name.get<std::string>());
    // A device not streaming at the announcement (reconnecting, configuring) is left out:
    // the pose goes to it again once the others have answered.
    if (m.contains("skipped") && m["skipped"].is_object()) {
      for (const auto& [name, state] : m["skipped"].items()) {
        if (state.is_string() && state.get<std::string>().rfind("replays", 0) != 0) {
          skipped_by_.insert(name);
        }
      }
    }
  } else if ((kind == "POSE_CAPTURED" || kind == "POSE_REJECTED") && ours) {
    const std::string device = m.value("device", "");
    waiting_.erase(device);
    if (kind == "POSE_REJECTED") rejected_by_.insert(device);
    Say({{"event", "answer"},
         {"index", p_},
         {"device", device},
         {"class", kind},
         {"saved", m.value("saved", false)},
         {"reason", m.value("reason", "")}});
  } else if (kind == "ERROR" && announced_ && outstanding_ > 0) {
    // A pose request refused (e.g. its device is not streaming): that device again later.
    // A retry to one device carries the device's name as its id.
    --outstanding_;
    Say({{"event", "refused"}, {"index", p_}, {"message", m.value("message", "")}});
    if (m.contains("id") && m["id"].is_string()) skipped_by_.insert(m["id"].get<std::string>());
  } else {
    return;
  }
  if (outstanding_ > 0 || !waiting_.empty()) return;
  OnAllAnswered(vt);
}

// Every request of this announcement answered.
void LiveSim::OnAllAnswered(double vt) {
  if (!accepted_any_ && retry_devices_.empty()) {
    // Refused outright (no device streaming yet): the same again in a moment. A retry to the
    // devices left out that is refused again counts as a retry (a unit that never streams must
    // not hold the table for ever).
    announced_ = false;
    retry_at_ = Clock::now() + std::chrono::milliseconds(500);
  } else if (rejected_by_.empty() && skipped_by_.empty()) {
    ++report_->captured;
    EndHold(vt);
  } else if (retries_left_-- > 0) {
    // Once more (the table holds still), to the devices that rejected it or were left out,
    // after a moment: what interrupted the stream may not be over yet.
    announced_ = false;
    retry_at_ = Clock::now() + std::chrono::milliseconds(250);
    retry_devices_ = rejected_by_;
    retry_devices_.insert(skipped_by_.begin(), skipped_by_.end());
  } else {
    ++report_->unanswered;
    EndHold(vt);
  }
}

// Announce the pose once the table has settled there, after the samples sent before (they
// are in the ptys unless the daemon has not read for a while; then after at most 0.5 s).
void LiveSim::AnnounceWhenDue(double vt) {
  const auto& events = *events_;
  bool flushed = true;
  for (const Device& d : devices_) flushed = flushed && d.out.empty();
  const bool due = p_ < events.size() && !announced_ && !start_holding_ &&
                   controller_.connected() && Clock::now() >= retry_at_ &&
                   vt >= events[p_].t_s + shift_s_;
  if (!due) {
    due_since_ = Clock::time_point::max();
  } else if (due_since_ == Clock::time_point::max()) {
    due_since_ = Clock::now();
  }
  if (!due || !(flushed || Clock::now() - due_since_ >= std::chrono::milliseconds(500))) return;
  due_since_ = Clock::time_point::max();
  const nlohmann::json request = PoseRequest();
  bool sent = true;
  outstanding_ = 0;
  if (retry_devices_.empty()) {
    sent = controller_.Send(request);
    outstanding_ = 1;
  } else {
    for (const auto& device : retry_devices_) {
      nlohmann::json one = request;
      one["device"] = device;
      one["id"] = device;
      sent = sent && controller_.Send(one);
      ++outstanding_;
    }
  }
  if (!sent) return;
  announced_ = true;
  accepted_any_ = false;
  ForgetAnswers();
  const TablePose& pose = events[p_].pose;
  nlohmann::json said = protocol::ToJson(pose);
  said["event"] = pose.is_rate() ? "rate" : "pose";
  said["index"] = p_;
  Say(said);
}

// The daemon's pose (or rate) command for pose p.
nlohmann::json LiveSim::PoseRequest() const {
  const TablePose& pose = (*events_)[p_].pose;
  nlohmann::json request = {{"cmd", "pose"},
                            {"index", p_},
                            {"phi_deg", pose.phi_rad * kDegPerRad},
                            {"gamma_deg", pose.gamma_rad * kDegPerRad},
                            {"psi_deg", pose.psi_rad * kDegPerRad}};
  if (pose.is_rate()) {
    // A rate segment: the table turns about one axis (docs/protocol.md "rate"); whole
    // revolutions of at least the session's dwell, as the simulator holds the rate.
    request = protocol::ToJson(pose);
    request["cmd"] = "rate";
    request["axis"] = request["rate_axis"];
    request.erase("rate_axis");
    request["index"] = p_;
    request["dwell_s"] = devices_[0].capture->session_options.dwell_s;
  }
  return request;
}

void LiveSim::ForgetAnswers() {
  waiting_.clear();
  rejected_by_.clear();
  skipped_by_.clear();
}

}  // namespace live

bool RunLiveSim(std::vector<LiveSimDevice>* sims, const LiveSimOptions& options,
                LiveSimReport* report, std::string* error) {
  return live::LiveSim(sims, options, report).Run(error);
}

}  // namespace turncal::sim
