#pragma once
// The registry's outbox (issue 24, docs/REGISTRY.md): every activated calibration, and every
// write into a device, goes to the registry through files in the state directory, so the
// station keeps working while the database is down and loses nothing:
//
//   outbox/SEQUENCE-KIND-LOCALID.json       an entry waiting (written atomically and fsynced
//                                           after the calibration's own file)
//   outbox/sent.log                         the entries the registry has committed, one local id
//                                           a line (appended after the commit)
//   outbox/rejected/                        entries the registry refused as malformed (SQLSTATE
//                                           class 22 or 23) or that are not entries: counted,
//                                           never retried (not even by the reconciliation),
//                                           never deleted
//
// Its own thread sends the entries oldest first, each in one transaction keyed by an
// idempotency key (station, device serial, model, version and the calibration's time): a crash
// between the commit and the entry's removal sends it again, and the registry keeps one row. At
// its start it also sends the active and earlier calibrations (calibrations/, history/) that
// sent.log does not list: a crash between the calibration's file and its outbox entry, or a
// registry configured after the station had calibrated, loses nothing either. The event loop
// only writes files and reads counters; the database is never waited for on it.

#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <thread>
#include <tuple>

#include "daemon/registry/registry_db.h"
#include "daemon/registry/registry_options.h"

namespace turncal::daemon {

class RegistryOutbox {
 public:
  RegistryOutbox(std::string state_dir, RegistryOptions options);
  ~RegistryOutbox();  // stops the thread (an attempt under way ends first: connect_timeout)
  RegistryOutbox(const RegistryOutbox&) = delete;
  RegistryOutbox& operator=(const RegistryOutbox&) = delete;

  // Creates outbox/ and starts the thread. False with a message (the directory cannot be made).
  bool Start(std::string* error);

  // An activated calibration (its document as calibrations/DEVICE.MODEL.json holds it; the
  // device's identity is its provenance's). Any thread. False with a message when the entry
  // cannot be written (then the start's reconciliation sends it).
  bool AddCalibration(const nlohmann::json& calibration, std::string* error);
  // A write into a device (daemon/state/device_write_record.h's history entry; `history_path` names
  // it: a later verification at a pose updates the same registry row). Any thread.
  bool AddDeviceWrite(const nlohmann::json& entry, const nlohmann::json& identity,
                      const std::string& history_path, std::string* error);

  // For `status`: station, connected, schema, depth (entries waiting), sent, already_there
  // (resends the registry held already), rejected, last_error and its time, last_sent time.
  nlohmann::json Status() const;

  // The idempotency key of a calibration document at `station`.
  static std::string CalibrationKey(const std::string& station, const nlohmann::json& calibration);

 private:
  void Run();
  // `unique`: an entry with the same local id already queued makes this one unnecessary (a
  // calibration reconciled while the worker adds it); a device write's later entry is not.
  bool WriteEntry(const std::string& kind, const std::string& local_id, bool unique,
                  nlohmann::json entry, std::string* error);
  void Reconcile();
  // One waiting entry to the registry. False when the database went away (the caller backs off).
  bool SendEntry(const std::string& path, bool hold_after_commit);
  void Reject(const std::string& path, const std::string& local_id, const std::string& why);
  // The last error for `status`; `connection`: the database went away with it.
  void NoteError(const std::string& error, bool connection = true);
  std::string Dir() const;

  const std::string state_dir_;
  const RegistryOptions options_;
  const std::string station_, host_;

  mutable std::mutex mutex_;
  std::condition_variable wake_;
  bool stop_ = false;
  bool added_ = false;                // an entry was added since the thread last looked
  bool reconcile_due_ = false;        // an entry could not be written: look at the state dir again
  std::uint64_t sequence_ = 0;        // orders the entries (continues after the highest left)
  std::set<std::string> queued_ids_;  // local ids with an entry in outbox/
  std::set<std::string> rejected_ids_;  // local ids in outbox/rejected/: never queued again
  std::int64_t depth_ = 0, sent_ = 0, already_there_ = 0, rejected_ = 0;
  bool connected_ = false;
  int schema_ = 0;
  std::string last_error_, last_error_time_, last_sent_time_;
  std::unique_ptr<RegistryDb> db_;  // the thread's connection (Cancel from the destructor)
  std::thread thread_;
};

// A service's outbox across reloads: started for [registry], kept while a reload leaves its
// options and the state directory as they were, and replaced otherwise -- the old one stopped off
// the caller's thread (a connection attempt under way may take connect_timeout, longer than the
// watchdog allows the event loop).
class RegistryHandle {
 public:
  ~RegistryHandle();
  // The outbox for `options` in `state_dir`; null without [registry], or when it cannot start
  // (logged: the station works without it, and the calibrations wait in their files for the
  // next start's reconciliation).
  const std::shared_ptr<RegistryOutbox>& Ensure(const RegistryOptions& options,
                                                const std::string& state_dir);
  const std::shared_ptr<RegistryOutbox>& get() const { return outbox_; }

 private:
  std::shared_ptr<RegistryOutbox> outbox_;
  std::tuple<std::string, std::string, std::string, double, int, std::string> options_;
};

}  // namespace turncal::daemon
