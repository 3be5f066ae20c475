// Writing a calibration into a device (daemon/device_write/device_writer.h, issue 23/35), driven
// without a socket or a daemon: the device writer against the device emulator (sim/device.h)
// through the real MIP dialogue (drivers/mip/mip_stored_write.h) on a synchronous link, the
// device's output made by the emulator from samples the simulator would send, and a loop that is
// a queue of posted work.
//
// A write is planned, averaged before, written, read back, averaged after and verified; the
// device's output is then re-expressed exactly into the values the calibrations were made with. A
// save the device refuses rolls back to the old values, and nothing is re-expressed. A write cut
// off (turncald killed mid-write) leaves its pending values in the record; the next turncald
// learns from the device's dialogue what it holds and re-expresses from that; so does a write
// whose replies were lost. A device that moved across the write
// is verified at the next captured pose, which passes when the pose agrees with the calibration
// and fails when it does not.
#include "daemon/device_write/device_writer.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <deque>
#include <filesystem>
#include <fstream>
#include <random>

#include "core/frames/reference.h"
#include "daemon/device/live_device.h"
#include "daemon/device_write/device_write_plan.h"
#include "daemon/station/model_pipeline.h"
#include "drivers/mip/mip_dialogue.h"
#include "drivers/mip/mip_stored.h"
#include "protocol/sequencer_json.h"
#include "sim/device.h"
#include "tests/support/virtual_link.h"

namespace turncal::daemon {
namespace {

namespace fs = std::filesystem;
namespace mip = drivers::mip;

constexpr double kRateHz = 100.0;
constexpr double kAccNoise = 0.002;  // m/s^2 per sample
constexpr double kGyrNoise = 1e-4;   // rad/s
constexpr double kMagNoise = 1e-4;   // Gauss
const drivers::ExchangeOptions kExchange{std::chrono::milliseconds(50), 3};

// The host's line to the emulated device, on a virtual clock. After `silent_after` commands the
// device still carries out what it receives but nothing comes back (the cable pulled mid-write).
class EmulatorLink : public testing_support::VirtualClockLink {
 public:
  explicit EmulatorLink(sim::DeviceEmulator* device) : device_(device) {}
  // Nothing comes back after `more` commands from now; -1: answers again.
  void GoSilentAfter(int more) { silent_after_ = more < 0 ? -1 : commands_ + more; }
  // The device hears nothing either after `more` commands from now; -1: it hears again.
  void GoDeafAfter(int more) { deaf_after_ = more < 0 ? -1 : commands_ + more; }

  bool Write(std::span<const std::uint8_t> bytes, std::string*) override {
    ++commands_;
    if (deaf_after_ >= 0 && commands_ > deaf_after_) return true;
    const std::vector<std::uint8_t> reply = device_->OnHostBytes(bytes);
    if (silent_after_ >= 0 && commands_ > silent_after_) return true;
    Queue(reply);
    return true;
  }

 private:
  sim::DeviceEmulator* device_;
  int commands_ = 0;
  int silent_after_ = -1, deaf_after_ = -1;
};

using Loop = std::deque<std::function<void()>>;

// A MIP device as turncald's LiveDevice presents it to the device writer: its dialogue and its
// stored write run on the emulator at once, and their results are posted to the loop, the write's
// outcome first and then the identity, as LiveDevice does.
class EmulatedDevice : public WritableDevice {
 public:
  EmulatedDevice(const sim::EmulatedIdentity& id, Loop* loop)
      : emulator_(sim::DeviceEmulator::Make(drivers::Protocol::kMip, id, kRateHz)),
        link_(emulator_.get()),
        loop_(loop) {
    spec_.name = "imu1";
    spec_.protocol = drivers::Protocol::kMip;
  }
  std::function<void(const nlohmann::json&)> on_identity;

  // The configuration dialogue; false when the device does not answer.
  bool Configure() {
    mip::Dialogue dialogue(&link_, kExchange);
    std::string error;
    const auto c = dialogue.Configure(kRateHz, &error);
    state_ = c ? "streaming" : "configure failed";
    identity_ = c ? MipIdentity(*c, kRateHz) : nlohmann::json();
    if (c && on_identity) on_identity(identity_);
    return c.has_value();
  }

  const drivers::DeviceSpec& spec() const override { return spec_; }
  const std::string& state() const override { return state_; }
  nlohmann::json identity() const override { return identity_; }
  // turncald is killed during the next write: the device takes its first `commands` commands,
  // and the write's end never reaches anybody.
  void KillTurncaldDuringWrite(int commands) { kill_after_ = commands; }

  bool RunStoredWrite(std::vector<mip::StoredWriteStep> steps, bool save, StoredWriteDone done,
                      std::string* error) override {
    if (state_ != "streaming") {
      *error = "imu1 is " + state_ + ", not streaming";
      return false;
    }
    state_ = "writing";
    mip::Dialogue dialogue(&link_, kExchange);
    if (kill_after_ >= 0) {
      link_.GoDeafAfter(kill_after_);
      mip::WriteStoredCalibration(&dialogue, steps, save);
      link_.GoDeafAfter(-1);
      kill_after_ = -1;
      return true;
    }
    const mip::StoredWriteOutcome outcome = mip::WriteStoredCalibration(&dialogue, steps, save);
    std::string configure_error;
    nlohmann::json identity;
    if (const auto c = dialogue.Configure(kRateHz, &configure_error)) {
      identity = MipIdentity(*c, kRateHz);
    }
    loop_->push_back([this, outcome, identity, configure_error, done] {
      done(outcome, identity, identity.is_null() ? configure_error : std::string());
      state_ = identity.is_null() ? "configure failed" : "streaming";
      if (!identity.is_null()) {
        identity_ = identity;
        if (on_identity) on_identity(identity_);
      }
    });
    return true;
  }

  // What the device outputs for a sample the simulator made with the factory values in use.
  Sample Output(Sample s) const {
    emulator_->ApplyStored(&s);
    return s;
  }
  sim::DeviceEmulator& emulator() { return *emulator_; }
  EmulatorLink& link() { return link_; }

 private:
  drivers::DeviceSpec spec_;
  std::unique_ptr<sim::DeviceEmulator> emulator_;
  EmulatorLink link_;
  Loop* loop_;
  int kill_after_ = -1;
  std::string state_ = "stopped";
  nlohmann::json identity_;
};

sim::EmulatedIdentity Gx5(const std::string& nonvolatile_path) {
  sim::EmulatedIdentity id;
  id.mip_nonvolatile_path = nonvolatile_path;
  return id;
}

class DeviceWriterTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("device_writer_test." + std::to_string(::getpid()) + "." +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "state");
    std::string error;
    model_ = MakeModel("accel13", ModelContext{}, &error);
    ASSERT_TRUE(model_) << error;
    noise_.sigma[kTriadAcc] = Eigen::Vector3d::Constant(kAccNoise);
    noise_.sigma[kTriadGyr] = Eigen::Vector3d::Constant(kGyrNoise);
    noise_.sigma[kTriadMag] = Eigen::Vector3d::Constant(kMagNoise);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string StateDir() const { return (dir_ / "state").string(); }

  // A device writer as turncald makes it (a new one: a restarted turncald).
  void StartWriter() {
    DeviceWriter::Hooks hooks;
    hooks.device = [this](const std::string& name) -> WritableDevice* {
      return device_ && name == "imu1" ? device_.get() : nullptr;
    };
    hooks.model_of = [this](const std::string& device,
                            const std::string& model) -> const MeasurementModel* {
      return device == "imu1" && model == "accel13" ? model_.get() : nullptr;
    };
    hooks.noise_of = [this](const std::string&) { return &noise_; };
    hooks.post = [this](std::function<void()> work) { loop_.push_back(std::move(work)); };
    hooks.publish = [this](const nlohmann::json& e) { events_.push_back(e); };
    hooks.history_written = [this](const std::string&, const nlohmann::json& entry) {
      histories_.push_back(entry);
    };
    hooks.now_ns = [this] { return now_ns_; };
    writer_ = std::make_unique<DeviceWriter>(hooks);
    StationOptions station;
    station.models = {"accel13"};
    writer_->Configure(StateDir(), station);
  }

  // The emulated device, configured; its identities go to the writer as LiveDevice's do.
  void PlugIn(const sim::EmulatedIdentity& id) {
    device_ = std::make_unique<EmulatedDevice>(id, &loop_);
    device_->on_identity = [this](const nlohmann::json& identity) {
      station_identity_ = writer_->OnIdentity("imu1", identity);
    };
    ASSERT_TRUE(device_->Configure());
  }

  // accel13's active calibration v3 (off nominal as a real sensor is), made on this device as it
  // is now, gate passed, in the state directory.
  void WriteCalibration() {
    theta_ = model_->nominal();
    std::mt19937_64 rng(7);
    std::normal_distribution<double> n;
    for (int i = 0; i < model_->num_parameters(); ++i) {
      const ParameterInfo& p = model_->parameters()[static_cast<std::size_t>(i)];
      if (p.kind != ParameterKind::kSensor) continue;
      theta_[i] += (p.unit == ParameterUnit::kAcceleration ? 0.05
                    : p.unit == ParameterUnit::kAngle      ? 0.01
                                                           : 0.02) *
                   n(rng);
    }
    covariance_ = Eigen::MatrixXd::Identity(theta_.size(), theta_.size()) * 1e-8;
    nlohmann::json params = nlohmann::json::object(), cov = nlohmann::json::array();
    for (int i = 0; i < model_->num_parameters(); ++i) {
      params[model_->parameters()[static_cast<std::size_t>(i)].name] = {{"value", theta_[i]},
                                                                        {"sigma", 1e-4}};
      nlohmann::json row = nlohmann::json::array();
      for (int k = 0; k < model_->num_parameters(); ++k) row.push_back(covariance_(i, k));
      cov.push_back(row);
    }
    const nlohmann::json calibration = {{"schema", 1},
                                        {"class", "CALIBRATION"},
                                        {"device", "imu1"},
                                        {"model", "accel13"},
                                        {"version", 3},
                                        {"params", params},
                                        {"covariance", cov},
                                        {"gate", {{"pass", true}}},
                                        {"provenance", {{"device_identity", device_->identity()}}}};
    fs::create_directories(dir_ / "state" / "calibrations");
    std::ofstream(dir_ / "state" / "calibrations" / "imu1.accel13.json") << calibration.dump(1);
  }

  // The simulator's sample at rest, level, with the factory values in use: gravity up the case's
  // -z, the Earth's field, white noise; the device's clock advancing at kRateHz.
  Sample Truth(const Eigen::Vector3d& acc_mps2 = Eigen::Vector3d(0, 0, -kStandardGravity_mps2)) {
    Sample s;
    s.device = "imu1";
    t_device_s_ += 1.0 / kRateHz;
    now_ns_ += static_cast<std::int64_t>(1e9 / kRateHz);
    s.t_device_s = t_device_s_;
    s.t_host_ns = now_ns_;
    s.acc_mps2 = acc_mps2 + kAccNoise * Eigen::Vector3d(n_(rng_), n_(rng_), n_(rng_));
    s.gyr_radps = kGyrNoise * Eigen::Vector3d(n_(rng_), n_(rng_), n_(rng_));
    s.mag =
        Eigen::Vector3d(0.2, 0.0, 0.4) + kMagNoise * Eigen::Vector3d(n_(rng_), n_(rng_), n_(rng_));
    return s;
  }

  // `count` samples of the device's output through the writer, the loop run after each (as the
  // event loop runs the work posted while a sample is handled); the last one as the station saw
  // it. `tilt_rad_per_sample`: the table turning about x meanwhile.
  Sample Stream(int count, double tilt_rad_per_sample = 0.0) {
    Sample seen;
    for (int i = 0; i < count; ++i) {
      tilt_rad_ += tilt_rad_per_sample;
      const Eigen::Vector3d g = Eigen::AngleAxisd(tilt_rad_, Eigen::Vector3d::UnitX()) *
                                Eigen::Vector3d(0, 0, -kStandardGravity_mps2);
      Sample scratch;
      seen = writer_->OnSample(device_->Output(Truth(g)), &scratch);
      RunLoop();
    }
    return seen;
  }

  void RunLoop() {
    while (!loop_.empty()) {
      auto work = std::move(loop_.front());
      loop_.pop_front();
      work();
    }
  }

  // The request, its messages collected.
  void Request(protocol::DeviceWriteArgs args) {
    writer_->Request(args, 0, [this](nlohmann::json m) { replies_.push_back(std::move(m)); });
    RunLoop();
  }
  static protocol::DeviceWriteArgs Write(bool save = false) {
    protocol::DeviceWriteArgs a;
    a.device = "imu1";
    a.model = "accel13";
    a.save = save;
    return a;
  }

  const nlohmann::json* Event(const std::string& kind) const {
    for (const auto& e : events_) {
      if (e.value("class", "") == kind) return &e;
    }
    return nullptr;
  }

  // The station's view of the device's output equals what the device output with the factory
  // values in use (f32 on the wire: 1e-6 relative).
  void ExpectReexpressedExactly() {
    for (int i = 0; i < 10; ++i) {
      const Sample truth = Truth();
      const Sample output = device_->Output(truth);
      Sample scratch;
      const Sample& seen = writer_->OnSample(output, &scratch);
      ASSERT_TRUE(seen.acc_mps2 && seen.mag);
      EXPECT_LT((*seen.acc_mps2 - *truth.acc_mps2).norm(), 1e-5 * truth.acc_mps2->norm())
          << seen.acc_mps2->transpose() << " vs " << truth.acc_mps2->transpose();
      EXPECT_LT((*seen.mag - *truth.mag).norm(), 1e-6);
    }
  }

  fs::path dir_;
  Loop loop_;
  std::unique_ptr<DeviceWriter> writer_;
  std::unique_ptr<EmulatedDevice> device_;
  std::unique_ptr<MeasurementModel> model_;
  NoiseProfile noise_;
  Eigen::VectorXd theta_;
  Eigen::MatrixXd covariance_;
  std::vector<nlohmann::json> events_, replies_, histories_;
  nlohmann::json station_identity_;
  std::mt19937_64 rng_{11};
  std::normal_distribution<double> n_;
  double t_device_s_ = 0.0, tilt_rad_ = 0.0;
  std::int64_t now_ns_ = 1'000'000'000;
};

TEST_F(DeviceWriterTest, AWriteIsPlannedWrittenVerifiedRecordedAndTheOutputReexpressed) {
  StartWriter();
  PlugIn(Gx5(""));
  WriteCalibration();
  const mip::StoredCalibration factory = *device_->emulator().mip_stored();

  protocol::DeviceWriteArgs dry = Write();
  dry.dry_run = true;
  Request(dry);
  ASSERT_EQ(replies_.size(), 1u);
  EXPECT_EQ(replies_[0].value("class", ""), "DEVICE_WRITE_PLAN") << replies_[0].dump();
  EXPECT_TRUE(replies_[0]["plan"].value("ok", false)) << replies_[0]["plan"].dump();
  EXPECT_FALSE(replies_[0]["plan"]["writes"].empty());
  EXPECT_FALSE(writer_->writing("imu1"));

  Request(Write());
  ASSERT_TRUE(writer_->writing("imu1"));
  Stream(200);  // the window before (2 s at 100 Hz), the write, then the window after
  EXPECT_TRUE(*device_->emulator().mip_stored()->accel_bias != *factory.accel_bias);
  Stream(200);
  ASSERT_FALSE(writer_->writing("imu1"));
  ASSERT_EQ(replies_.size(), 2u);
  const nlohmann::json& written = replies_[1];
  EXPECT_EQ(written.value("class", ""), "DEVICE_WRITTEN");
  EXPECT_TRUE(written.value("ok", false)) << written.dump(1);
  EXPECT_EQ(written.value("state", ""), "written");
  EXPECT_TRUE(written["verification"].value("pass", false)) << written["verification"].dump(1);
  // Each axis of the accelerometer compared, within the limit of a 0.1 % false alarm.
  for (const auto& z : written["verification"]["triads"]["acc"]["z"]) {
    EXPECT_LE(std::abs(z.get<double>()), VerifyZLimit(3));
  }
  ASSERT_TRUE(Event("DEVICE_WRITTEN"));
  ASSERT_EQ(histories_.size(), 1u);
  EXPECT_TRUE(fs::exists(histories_[0].value("history", "")));

  // The record: what the device holds, bit for bit; the values the calibrations see.
  const DeviceWriteRecord* record = writer_->record("imu1");
  ASSERT_TRUE(record);
  EXPECT_TRUE(SameStoredCalibration(record->in_device, *device_->emulator().mip_stored()));
  EXPECT_TRUE(SameStoredCalibration(record->as_if, factory));
  EXPECT_FALSE(record->pending);
  DeviceWriteRecord on_disk;
  bool exists = false;
  std::string error;
  ASSERT_TRUE(ReadDeviceWriteRecord(StateDir(), "imu1", &on_disk, &exists, &error)) << error;
  ASSERT_TRUE(exists);
  EXPECT_TRUE(SameStoredCalibration(on_disk.in_device, record->in_device));
  // The station's identity says what its calibrations see, and that the output is re-expressed.
  EXPECT_TRUE(station_identity_.contains("output_reexpressed")) << station_identity_.dump();
  ExpectReexpressedExactly();
}

TEST_F(DeviceWriterTest, ASaveTheDeviceRefusesRollsBackAndNothingIsReexpressed) {
  StartWriter();
  // The storage's folder is missing: the device refuses the save (NACK 4).
  PlugIn(Gx5((dir_ / "gone" / "SIM0001.nvm.json").string()));
  WriteCalibration();
  const mip::StoredCalibration factory = *device_->emulator().mip_stored();
  Request(Write(/*save=*/true));
  Stream(200);
  ASSERT_FALSE(writer_->writing("imu1"));
  ASSERT_EQ(replies_.size(), 1u);
  EXPECT_FALSE(replies_[0].value("ok", true)) << replies_[0].dump(1);
  EXPECT_EQ(replies_[0].value("state", ""), "rolled_back");
  EXPECT_TRUE(SameStoredCalibration(*device_->emulator().mip_stored(), factory));
  const DeviceWriteRecord* record = writer_->record("imu1");
  ASSERT_TRUE(record);
  EXPECT_TRUE(SameStoredCalibration(record->in_device, factory));
  EXPECT_FALSE(record->reexpress());
  const Sample truth = Truth();
  Sample scratch;
  const Sample out = device_->Output(truth);
  EXPECT_EQ(&writer_->OnSample(out, &scratch), &out);  // passed through as it is
}

TEST_F(DeviceWriterTest, AWriteCutOffIsSettledByWhatTheDeviceSaysItHoldsNext) {
  StartWriter();
  PlugIn(Gx5((dir_ / "SIM0001.nvm.json").string()));
  WriteCalibration();
  const mip::StoredCalibration factory = *device_->emulator().mip_stored();
  // turncald is killed just after the device took the bias's write (set to idle, write).
  device_->KillTurncaldDuringWrite(2);
  Request(Write(/*save=*/true));
  Stream(200);
  EXPECT_TRUE(writer_->writing("imu1"));
  EXPECT_TRUE(replies_.empty());
  // The device holds the new bias; the record says what the write was putting in.
  EXPECT_FALSE(SameStoredCalibration(*device_->emulator().mip_stored(), factory));
  DeviceWriteRecord on_disk;
  bool exists = false;
  std::string error;
  ASSERT_TRUE(ReadDeviceWriteRecord(StateDir(), "imu1", &on_disk, &exists, &error)) << error;
  ASSERT_TRUE(exists && on_disk.pending);
  EXPECT_TRUE(SameStoredCalibration(*on_disk.pending, *device_->emulator().mip_stored()));
  EXPECT_TRUE(SameStoredCalibration(on_disk.in_device, factory));

  // The next turncald: the device's dialogue says what it holds, and the output is re-expressed
  // from that.
  StartWriter();
  ASSERT_TRUE(device_->Configure());
  const DeviceWriteRecord* record = writer_->record("imu1");
  ASSERT_TRUE(record);
  EXPECT_FALSE(record->pending);
  EXPECT_TRUE(SameStoredCalibration(record->in_device, *device_->emulator().mip_stored()));
  EXPECT_TRUE(SameStoredCalibration(record->as_if, factory));
  EXPECT_TRUE(record->nonvolatile_changed);  // the write was to be saved: a restore saves too
  ASSERT_TRUE(ReadDeviceWriteRecord(StateDir(), "imu1", &on_disk, &exists, &error)) << error;
  EXPECT_FALSE(on_disk.pending);
  ExpectReexpressedExactly();
}

TEST_F(DeviceWriterTest, AWriteWhoseEndIsUnknownIsSettledByTheNextDialogue) {
  StartWriter();
  PlugIn(Gx5((dir_ / "SIM0001.nvm.json").string()));
  WriteCalibration();
  const mip::StoredCalibration factory = *device_->emulator().mip_stored();
  Request(Write(/*save=*/true));
  // The replies stop after set-to-idle and the write; the device still carries out the rest,
  // the rollback too.
  device_->link().GoSilentAfter(2);
  Stream(200);
  ASSERT_FALSE(writer_->writing("imu1"));
  ASSERT_EQ(replies_.size(), 1u);
  EXPECT_FALSE(replies_[0].value("ok", true));
  EXPECT_EQ(replies_[0].value("state", ""), "unknown") << replies_[0].dump(1);
  EXPECT_FALSE(replies_[0].value("configure_error", "").empty());
  const DeviceWriteRecord* record = writer_->record("imu1");
  ASSERT_TRUE(record && record->pending);  // nobody knows what the device holds

  // The line answers again: the device holds the old values (the rollback reached it).
  device_->link().GoSilentAfter(-1);
  ASSERT_TRUE(device_->Configure());
  record = writer_->record("imu1");
  ASSERT_TRUE(record);
  EXPECT_FALSE(record->pending);
  EXPECT_TRUE(SameStoredCalibration(record->in_device, factory));
  EXPECT_FALSE(record->reexpress());
  // Whether a save went out is not known: kept as if it did (a restore then saves too).
  EXPECT_TRUE(record->nonvolatile_changed);
}

// The pose record the station captured at `pose`: the device's mean output there as the station
// sees it (re-expressed into the values the calibration was made with), `offset` added.
nlohmann::json PoseCaptured(const MeasurementModel& model, const Eigen::VectorXd& theta,
                            const TablePose& pose, const Eigen::Vector3d& offset) {
  PoseRecord r;
  r.pose = pose;
  TriadStats acc;
  acc.count = 1000;
  acc.covariance = Eigen::Matrix3d::Identity() * kAccNoise * kAccNoise;
  acc.mean = model.Predict(theta, pose) + offset;
  r.acc = acc;
  r.t_start_s = 100.0;
  r.t_end_s = 110.0;
  return {{"class", "POSE_CAPTURED"},
          {"device", "imu1"},
          {"index", 7},
          {"record", protocol::ToJson(r)}};
}

TEST_F(DeviceWriterTest, AWriteTheDeviceMovedAcrossIsVerifiedAtTheNextPose) {
  for (const bool agrees : {true, false}) {
    SCOPED_TRACE(agrees ? "the pose agrees" : "the pose is 25 of its sigma off");
    fs::remove_all(dir_ / "state");
    events_.clear(), replies_.clear(), histories_.clear();
    tilt_rad_ = 0.0;
    StartWriter();
    PlugIn(Gx5(""));
    WriteCalibration();
    Request(Write());
    Stream(200);
    Stream(200, 0.002);  // the table turns during the window after the write: 23 degrees
    ASSERT_EQ(replies_.size(), 1u);
    const nlohmann::json& v = replies_[0]["verification"];
    EXPECT_TRUE(replies_[0].value("ok", false));
    EXPECT_FALSE(v.value("pass", true));
    EXPECT_TRUE(v.value("deferred", false)) << v.dump(1);
    EXPECT_TRUE(writer_->verification_pending("imu1"));

    const TablePose pose{0.3, -0.4, 1.1};
    // The record mean's sigma is 6e-5 m/s^2; 25 of it is 1.5e-3 (beyond the calibration's).
    const Eigen::Vector3d offset = agrees ? Eigen::Vector3d::Zero() : Eigen::Vector3d(0.05, 0, 0);
    writer_->OnPoseCaptured(PoseCaptured(*model_, theta_, pose, offset));
    EXPECT_FALSE(writer_->verification_pending("imu1"));
    const nlohmann::json* verified = Event("DEVICE_WRITE_VERIFIED");
    ASSERT_TRUE(verified);
    EXPECT_EQ((*verified)["verification"].value("pass", !agrees), agrees)
        << (*verified)["verification"].dump(1);
    EXPECT_EQ((*verified)["verification"].value("index", -1), 7);
    // The history entry is completed with it, and goes to the registry again.
    std::ifstream in((*verified).value("history", ""));
    const nlohmann::json entry = nlohmann::json::parse(in, nullptr, false);
    ASSERT_TRUE(entry.is_object());
    EXPECT_EQ(entry["verification_at_pose"].value("pass", !agrees), agrees);
    EXPECT_EQ(histories_.size(), 2u);
  }
}

TEST_F(DeviceWriterTest, RefusalsNameTheirReason) {
  StartWriter();
  Request(Write());
  ASSERT_EQ(replies_.size(), 1u);
  EXPECT_NE(replies_[0].value("message", "").find("no device 'imu1'"), std::string::npos)
      << replies_[0].dump();
  PlugIn(Gx5(""));
  Request(Write());  // no calibration yet
  EXPECT_NE(replies_.back().value("message", "").find("has no active calibration of accel13"),
            std::string::npos)
      << replies_.back().dump();
  protocol::DeviceWriteArgs restore;
  restore.device = "imu1";
  restore.restore = true;
  Request(restore);
  EXPECT_NE(replies_.back().value("message", "").find("nothing to restore"), std::string::npos)
      << replies_.back().dump();
  WriteCalibration();
  protocol::DeviceWriteArgs stale = Write();
  stale.version = 2;  // the plan the client saw
  Request(stale);
  EXPECT_NE(replies_.back().value("message", "").find("the plan shown was for version 2"),
            std::string::npos)
      << replies_.back().dump();
  EXPECT_FALSE(writer_->writing("imu1"));
}

}  // namespace
}  // namespace turncal::daemon
