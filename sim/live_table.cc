#include <fmt/format.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include <chrono>

#include "sim/live_session.h"

// The table's side of a live session (sim/live_session.h): resting, holding and leaving poses,
// unplugs, the devices' streams and dialogues, and the session's end.
namespace turncal::sim::live {

// At rest at home: ask the daemon whether every device's noise is measured; hold the start's
// samples until it is (or answer_timeout_s passed).
void LiveSim::RestAtHome(double vt) {
  if (start_rest_ && controller_.connected() && Clock::now() >= status_at_) {
    status_at_ = Clock::now() + std::chrono::milliseconds(250);
    controller_.Send({{"cmd", "status"}});
  }
  if (start_rest_ && !start_holding_ && vt >= start_s_ + shift_s_) {
    start_holding_ = true;
    BeginHold(0.0, start_s_, start_s_ + shift_s_);
  }
  if (start_holding_ && start_rest_ && HeldWallS(vt) > options_.answer_timeout_s) {
    Say({{"event", "start_rest"}, {"state", "gave up waiting for the noise"}, {"after_s", vt}});
    start_rest_ = false;
  }
  if (start_holding_ && !start_rest_) {
    start_holding_ = false;
    ShiftPastHold(vt);
  }
}

// The table holds while the pose is not answered, up to answer_timeout_s.
void LiveSim::HoldWhileUnanswered(double vt) {
  const auto& events = *events_;
  if (p_ < events.size() && !holding_ && !start_holding_ &&
      vt >= events[p_].dwell_end_s + shift_s_) {
    holding_ = true;
    BeginHold(events[p_].t_s, events[p_].dwell_end_s, events[p_].dwell_end_s + shift_s_);
  }
  if (holding_ && HeldWallS(vt) > options_.answer_timeout_s) {
    Say({{"event", "gave_up"}, {"index", p_}, {"after_s", vt - hold_start_s_}});
    ++report_->unanswered;
    EndHold(vt);
  }
}

// Unplugs halfway through a pose's dwell (announced, not yet answered).
void LiveSim::UnplugMidPose(double vt) {
  const auto& events = *events_;
  for (std::size_t k = 0; k < options_.unplugs.size(); ++k) {
    if (!unplug_done_[k] && options_.unplugs[k].mid &&
        options_.unplugs[k].pose == static_cast<int>(p_) && p_ < events.size() && announced_ &&
        vt >= 0.5 * (events[p_].t_s + events[p_].dwell_end_s) + shift_s_) {
      Unplug(k, vt);
    }
  }
}

// The unplugged devices whose time has come appear again, powered up afresh.
bool LiveSim::Replug(double vt, std::string* error) {
  for (std::size_t i = 0; i < devices_.size(); ++i) {
    Device& d = devices_[i];
    if (!d.unplugged || vt < d.replug_vt) continue;
    if (!live::OpenDevice(&d, error)) return false;
    d.emulator = live::PowerUp(d, i, options_);
    d.unplugged = false;
    Say({{"event", "replugged"}, {"device", d.path}});
  }
  return true;
}

// The devices stream what is due; true when every pose is done and every sample sent.
bool LiveSim::Stream(double vt, double turn_gap_s) {
  bool done = p_ >= events_->size();
  for (Device& d : devices_) {
    if (holding_ || start_holding_ || end_holding_) {
      StreamHeld(&d, vt, turn_gap_s);
    } else {
      StreamPlanned(&d, vt, turn_gap_s);
    }
    done = done && d.next >= d.capture->session.samples.size();
    live::Flush(&d);
  }
  return done;
}

// While the table holds: the held pose's stationary samples again, forwards then backwards,
// device time and counter running on.
void LiveSim::StreamHeld(Device* d, double vt, double turn_gap_s) {
  const auto& samples = d->capture->session.samples;
  while (d->clone_due_s <= vt && !d->hold_samples.empty()) {
    const std::size_t n = d->hold_samples.size();
    const std::size_t at = d->clones % (2 * n);
    Sample s = samples[d->hold_samples[at < n ? at : 2 * n - 1 - at]];
    s.t_device_s = d->last_device_s + d->period_s;
    if (s.counter) s.counter = d->last_counter + 1;
    live::Emit(d, s, &errors_, vt, turn_gap_s);
    ++d->clones;
    d->clone_due_s += d->period_s;
  }
}

// Otherwise: the session's own samples up to now (shifted past the holds so far), not beyond
// the current pose's planned dwell.
void LiveSim::StreamPlanned(Device* d, double vt, double turn_gap_s) {
  const auto& samples = d->capture->session.samples;
  const auto& events = *events_;
  while (d->next < samples.size() &&
         static_cast<double>(samples[d->next].t_host_ns) * 1e-9 + d->shift_s <= vt &&
         (p_ >= events.size() ||
          static_cast<double>(samples[d->next].t_host_ns) * 1e-9 < events[p_].dwell_end_s)) {
    Sample s = samples[d->next++];
    if (s.t_device_s) *s.t_device_s += d->device_shift_s;
    if (s.counter) *s.counter += d->counter_shift;
    live::Emit(d, s, &errors_, vt, turn_gap_s);
  }
}

// After the last pose the table stays there hold_end_s, the devices streaming its samples.
void LiveSim::HoldAtEnd(bool done, double vt) {
  const auto& events = *events_;
  if (!done || !(options_.hold_end_s > 0) || end_holding_ || events.empty()) return;
  end_holding_ = true;
  end_hold_until_s_ = vt + options_.hold_end_s;
  BeginHold(events.back().t_s, events.back().dwell_end_s, vt);
  Say({{"event", "holding_end"}, {"index", events.size() - 1}, {"for_s", options_.hold_end_s}});
}

// A command whose reply is to be lost (a 3DM command in one read: the daemon writes each
// command whole): carried out, the reply dropped, once. True when this read's reply is lost.
bool LiveSim::LoseReply(std::size_t i, const std::uint8_t* buffer, ssize_t n,
                        std::size_t reply_bytes) {
  for (std::size_t k = 0; k < lose_left_.size(); ++k) {
    const auto& l = options_.lose_replies[k];
    for (ssize_t at = 0; lose_left_[k] && at + 6 < n; ++at) {
      if (buffer[at] == 0x75 && buffer[at + 1] == 0x65 && buffer[at + 2] == 0x0C &&
          buffer[at + 5] == l.descriptor && buffer[at + 6] == l.function) {
        lose_left_[k] = false;
        Say({{"event", "reply_lost"},
             {"device", devices_[i].path},
             {"command", fmt::format("0x0C 0x{:02X} function {}", l.descriptor, l.function)},
             {"reply_bytes", reply_bytes}});
        return true;
      }
    }
  }
  return false;
}

// Waits for the devices' commands (or 1 ms) and queues the emulators' replies.
void LiveSim::AnswerDialogues() {
  std::vector<pollfd> fds;
  for (const Device& d : devices_) fds.push_back({d.fd, POLLIN, 0});  // fd -1: ignored
  ::poll(fds.data(), fds.size(), 1);
  for (std::size_t i = 0; i < devices_.size(); ++i) {
    if (!(fds[i].revents & POLLIN)) continue;
    std::uint8_t buffer[4096];
    if (devices_[i].fd < 0) continue;
    const ssize_t n = ::read(devices_[i].fd, buffer, sizeof(buffer));
    if (n <= 0) continue;
    const auto reply = devices_[i].emulator->OnHostBytes({buffer, static_cast<std::size_t>(n)});
    if (LoseReply(i, buffer, n, reply.size())) continue;
    const std::size_t from = devices_[i].out.size();
    devices_[i].out.append(reply.begin(), reply.end());
    errors_.Apply(&devices_[i], from);
    live::Flush(&devices_[i]);
  }
}

// Before the ptys close (closing discards what the daemon has not read): wait until every
// queued byte is written and the slave side has held nothing for 100 ms, up to 5 s. One empty
// look is not enough: a pty hands what the master wrote to the slave's line discipline from a
// kernel work queue, so FIONREAD can read 0 just after a write, before the bytes arrive.
void LiveSim::DrainPtys() {
  int quiet_ms = 0;
  for (int waited_ms = 0; waited_ms < 5000 && quiet_ms < 100; waited_ms += 10) {
    bool quiet = true;
    for (Device& d : devices_) {
      const std::uint64_t before = d.written;
      live::Flush(&d);
      int unread = 0;
      if (d.slave_fd >= 0 && ::ioctl(d.slave_fd, FIONREAD, &unread) == 0 && unread > 0) {
        quiet = false;
      }
      quiet = quiet && d.written == before && (d.out.empty() || d.fd < 0);
    }
    quiet_ms = quiet ? quiet_ms + 10 : 0;
    ::usleep(10'000);
  }
}

// Each device's figures into the report; the ptys closed.
void LiveSim::Finish() {
  for (std::size_t i = 0; i < devices_.size(); ++i) {
    Device& d = devices_[i];
    if (d.episode_dropped > 0) live::SayDropped(d, SessionNow());  // still dropping at the end
    report_->frames_sent[i] = d.sent;
    report_->frames_withheld[i] = d.withheld;
    report_->frames_dropped[i] = d.dropped;
    report_->bytes_written.push_back(d.written);
    report_->bits_flipped.push_back(d.flipped);
    report_->bytes_lost_unplugged.push_back(d.lost_unplugged);
    report_->frames_unplugged.push_back(d.unplugged_frames);
    report_->unplugs.push_back(d.unplugs);
    live::Close(&d);
  }
}

// The k-th unplug of the options: its device goes away for unplug_s.
void LiveSim::Unplug(std::size_t k, double vt) {
  const auto& u = options_.unplugs[k];
  unplug_done_[k] = true;
  Device& d = devices_[static_cast<std::size_t>(u.device)];
  if (d.unplugged) return;
  live::Unplug(&d, vt + options_.unplug_s);
  Say({{"event", "unplugged"},
       {"device", d.path},
       {"pose", u.pose},
       {"where", u.mid ? "mid-pose" : "between poses"},
       {"replug_in_s", options_.unplug_s}});
}

// The samples of [t0, t1) are streamed again (forwards, then backwards: no step at the seams).
void LiveSim::BeginHold(double t0_s, double t1_s, double at_vt) {
  for (Device& d : devices_) {
    d.hold_samples.clear();
    const auto& samples = d.capture->session.samples;
    for (std::size_t k = 0; k < samples.size(); ++k) {
      const double t = static_cast<double>(samples[k].t_host_ns) * 1e-9;
      if (t >= t0_s && t < t1_s) d.hold_samples.push_back(k);
    }
    d.clones = 0;
    d.clone_due_s = at_vt;
  }
  hold_start_s_ = at_vt;
}

// The samples after a hold come that much later, on the device's clock and counter too.
void LiveSim::ShiftPastHold(double vt) {
  for (Device& d : devices_) {
    d.shift_s += static_cast<double>(d.clones) * d.period_s;
    d.device_shift_s += static_cast<double>(d.clones) * d.period_s;
    d.counter_shift += static_cast<std::uint32_t>(d.clones);
    d.clones = 0;
  }
  report_->held_s += vt - hold_start_s_;
  shift_s_ += vt - hold_start_s_;
}

// The table leaves pose p (unplugging the devices due between poses) for the next.
void LiveSim::EndHold(double vt) {
  for (std::size_t k = 0; k < options_.unplugs.size(); ++k) {
    if (!unplug_done_[k] && !options_.unplugs[k].mid &&
        options_.unplugs[k].pose == static_cast<int>(p_)) {
      Unplug(k, vt);
    }
  }
  if (holding_) ShiftPastHold(vt);
  holding_ = false;
  announced_ = false;
  ForgetAnswers();
  retry_devices_.clear();
  retries_left_ = options_.retries;
  ++p_;
}

}  // namespace turncal::sim::live
