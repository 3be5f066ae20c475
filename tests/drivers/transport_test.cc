// Transports against real peers: a socat pty pair carries a simulated stream into the serial
// transport; killing socat mid-stream is a disconnect and a reconnect attempt, not a crash; a
// local TCP server; a capture replayed at full speed.
#include "drivers/transport/transport.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/write.hpp>
#include <filesystem>
#include <fstream>
#include <functional>
#include <thread>

#include "drivers/capture/tcap.h"
#include "drivers/xbus/xbus_decoder.h"
#include "drivers/xbus/xbus_encoder.h"

extern char** environ;

namespace turncal::drivers {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;

class Collect : public DecoderSink {
 public:
  void OnFrame(const FrameView&) override {}
  void OnSample(const Sample& s) override { samples.push_back(s); }
  std::vector<Sample> samples;
};

// Runs `io` until `done()` holds or `limit` passes (checked every 5 ms). The tests wait for what
// they expect to happen rather than for a fixed time: beside the live tests on a loaded 2-core
// host, 200 ms were not always enough for two connection attempts (CI, 2026-11-23).
bool RunUntil(boost::asio::io_context& io, const std::function<bool()>& done,
              std::chrono::milliseconds limit = std::chrono::seconds(10)) {
  io.restart();
  boost::asio::steady_timer poll_timer(io);
  std::function<void()> poll = [&] {
    poll_timer.expires_after(std::chrono::milliseconds(5));
    poll_timer.async_wait([&](const boost::system::error_code& ec) {
      if (ec) return;
      if (done()) {
        io.stop();
        return;
      }
      poll();
    });
  };
  poll();
  io.run_for(limit);
  poll_timer.cancel();
  return done();
}

Sample Numbered(int i) {
  Sample s;
  s.counter = static_cast<std::uint32_t>(i);
  s.t_device_s = i * 0.01;
  s.acc_mps2 = Eigen::Vector3d(0.001 * i, -9.8, 0.5);
  s.gyr_radps = Eigen::Vector3d(0.01, -0.02, 0.001 * i);
  s.mag = Eigen::Vector3d(0.2, 0.01, 0.4);
  return s;
}

struct Socat {
  pid_t pid = -1;
  fs::path dir, device, peer;
  bool Start() {
    dir = fs::temp_directory_path() / ("turncal_pty_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    device = dir / "device";
    peer = dir / "peer";
    const std::string a = "pty,raw,echo=0,link=" + device.string();
    const std::string b = "pty,raw,echo=0,link=" + peer.string();
    char* argv[] = {const_cast<char*>("socat"), const_cast<char*>(a.c_str()),
                    const_cast<char*>(b.c_str()), nullptr};
    if (posix_spawnp(&pid, "socat", nullptr, nullptr, argv, environ) != 0) return false;
    for (int i = 0; i < 100 && !(fs::exists(device) && fs::exists(peer)); ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return fs::exists(device) && fs::exists(peer);
  }
  void Kill() {
    if (pid > 0) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, nullptr, 0);
      pid = -1;
    }
  }
  ~Socat() {
    Kill();
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
};

bool HaveSocat() { return std::system("command -v socat > /dev/null 2>&1") == 0; }

TEST(SerialTransport, PtyCarriesASimulatedStreamAndSurvivesItsPeerDying) {
  if (!HaveSocat()) GTEST_SKIP() << "socat is not installed (./scripts/setup installs it)";
  Socat socat;
  ASSERT_TRUE(socat.Start());
  boost::asio::io_context io;
  std::string error;
  TransportOptions options;
  options.reconnect_initial = std::chrono::milliseconds(20);
  auto transport = MakeTransport(io, socat.device.string(), 115200, options, &error);
  ASSERT_NE(transport, nullptr) << error;
  Collect sink;
  XbusDecoder decoder("pty", &sink);
  std::vector<std::pair<TransportStatus, std::string>> statuses;
  transport->Start([&](std::span<const std::uint8_t> b, std::int64_t t) { decoder.Push(b, t); },
                   [&](TransportStatus s, const std::string& m) { statuses.emplace_back(s, m); });
  constexpr int kSamples = 400;
  std::thread writer([&] {
    std::ofstream out(socat.peer, std::ios::binary);
    for (int i = 0; i < kSamples; ++i) {
      const Bytes frame = xbus::MtData2(Numbered(i));
      out.write(reinterpret_cast<const char*>(frame.data()),
                static_cast<std::streamsize>(frame.size()));
      if (i % 50 == 49) {
        out.flush();
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
      }
    }
    out.flush();
  });
  RunUntil(io, [&] { return sink.samples.size() >= kSamples; });
  writer.join();
  ASSERT_EQ(sink.samples.size(), static_cast<std::size_t>(kSamples));
  for (int i = 0; i < kSamples; ++i) {
    EXPECT_EQ(sink.samples[i].counter, static_cast<std::uint32_t>(i));
    EXPECT_NEAR(sink.samples[i].acc_mps2->x(), Numbered(i).acc_mps2->x(), 1e-6);
  }
  EXPECT_EQ(decoder.counters().bad_checksums, 0u);
  ASSERT_FALSE(statuses.empty());
  EXPECT_EQ(statuses[0].first, TransportStatus::kOpened);
  EXPECT_NE(statuses[0].second.find("termios"), std::string::npos) << statuses[0].second;

  // The peer dies: a disconnect with a message, then attempts to reopen; nothing crashes.
  socat.Kill();
  const auto count = [&](TransportStatus wanted) {
    return std::count_if(statuses.begin(), statuses.end(),
                         [&](const auto& status) { return status.first == wanted; });
  };
  RunUntil(io, [&] {
    return count(TransportStatus::kDisconnected) >= 1 && count(TransportStatus::kOpenFailed) >= 1;
  });
  bool disconnected = false;
  int reopen_attempts = 0;
  for (const auto& [s, m] : statuses) {
    if (s == TransportStatus::kDisconnected) {
      disconnected = true;
      EXPECT_NE(m.find("device gone"), std::string::npos) << m;
    }
    if (s == TransportStatus::kOpenFailed) ++reopen_attempts;
  }
  EXPECT_TRUE(disconnected);
  EXPECT_GE(reopen_attempts, 1);
  EXPECT_EQ(transport->counters().disconnects, 1u);
  EXPECT_FALSE(transport->is_open());
  std::string write_error;
  EXPECT_FALSE(transport->Write(Bytes{1, 2, 3}, &write_error));
  EXPECT_NE(write_error.find("not open"), std::string::npos);
  transport->Stop();
}

TEST(TcpTransport, ReceivesFromAServerAndReconnectsWhenItCloses) {
  boost::asio::io_context io;
  boost::asio::ip::tcp::acceptor acceptor(io, {boost::asio::ip::address_v4::loopback(), 0});
  const int port = acceptor.local_endpoint().port();
  const Bytes payload = xbus::MtData2(Numbered(7));
  int accepted = 0;
  std::function<void()> serve = [&] {
    auto socket = std::make_shared<boost::asio::ip::tcp::socket>(io);
    acceptor.async_accept(*socket, [&, socket](const boost::system::error_code& ec) {
      if (ec) return;
      ++accepted;
      boost::asio::write(*socket, boost::asio::buffer(payload));
      socket->close();  // the server drops the connection after one message
      if (accepted < 2) serve();
    });
  };
  serve();
  std::string error;
  TransportOptions options;
  options.reconnect_initial = std::chrono::milliseconds(10);
  auto transport = MakeTransport(io, "tcp://127.0.0.1:" + std::to_string(port), 0, options, &error);
  ASSERT_NE(transport, nullptr) << error;
  Collect sink;
  XbusDecoder decoder("tcp", &sink);
  int disconnects = 0;
  transport->Start([&](std::span<const std::uint8_t> b, std::int64_t t) { decoder.Push(b, t); },
                   [&](TransportStatus s, const std::string&) {
                     if (s == TransportStatus::kDisconnected && ++disconnects == 2) io.stop();
                   });
  io.run_for(std::chrono::seconds(5));
  EXPECT_EQ(accepted, 2);
  EXPECT_EQ(sink.samples.size(), 2u);
  EXPECT_EQ(transport->counters().opens, 2u);
  transport->Stop();
}

// Stopping from inside the data handler (a client that has seen enough) must not touch the closed
// stream (found by review: it dereferenced it).
TEST(TcpTransport, StopFromTheDataHandlerIsSafe) {
  boost::asio::io_context io;
  boost::asio::ip::tcp::acceptor acceptor(io, {boost::asio::ip::address_v4::loopback(), 0});
  boost::asio::ip::tcp::socket peer(io);
  acceptor.async_accept(peer, [&](const boost::system::error_code& ec) {
    if (!ec) boost::asio::write(peer, boost::asio::buffer("hello", 5));
  });
  std::string error;
  auto transport = MakeTransport(
      io, "tcp://127.0.0.1:" + std::to_string(acceptor.local_endpoint().port()), 0, {}, &error);
  ASSERT_NE(transport, nullptr) << error;
  int chunks = 0;
  transport->Start(
      [&](std::span<const std::uint8_t>, std::int64_t) {
        ++chunks;
        transport->Stop();
      },
      [](TransportStatus, const std::string&) {});
  RunUntil(io, [&] { return chunks >= 1; });
  io.restart();
  io.run_for(std::chrono::milliseconds(100));  // nothing more arrives once stopped
  EXPECT_EQ(chunks, 1);
  EXPECT_FALSE(transport->is_open());
}

TEST(TcpTransport, ARefusedConnectionIsRetriedWithoutBlocking) {
  boost::asio::io_context io;
  int port = 0;
  {
    boost::asio::ip::tcp::acceptor probe(io, {boost::asio::ip::address_v4::loopback(), 0});
    port = probe.local_endpoint().port();
  }  // closed again: nothing listens there
  std::string error;
  TransportOptions options;
  options.reconnect_initial = std::chrono::milliseconds(10);
  auto transport = MakeTransport(io, "tcp://127.0.0.1:" + std::to_string(port), 0, options, &error);
  ASSERT_NE(transport, nullptr) << error;
  std::vector<std::string> failures;
  transport->Start([](std::span<const std::uint8_t>, std::int64_t) {},
                   [&](TransportStatus s, const std::string& m) {
                     if (s == TransportStatus::kOpenFailed) failures.push_back(m);
                   });
  // Retried: a second attempt follows the first (10 ms, then 20 ms later).
  ASSERT_TRUE(RunUntil(io, [&] { return failures.size() >= 2; }))
      << failures.size() << " connection attempt(s) in 10 s";
  EXPECT_NE(failures[0].find("cannot connect"), std::string::npos) << failures[0];
  EXPECT_FALSE(transport->is_open());
  transport->Stop();
}

TEST(ReplayTransport, DeliversEveryByteAndEventInOrderAtFullSpeed) {
  const auto path = fs::temp_directory_path() / "turncal_replay_test.tcap";
  std::string error;
  CaptureHeader header;
  header.devices.push_back({"mti", Protocol::kXbus, 115200, std::nullopt, std::nullopt});
  auto w = CaptureWriter::Create(path.string(), header, &error);
  ASSERT_NE(w, nullptr) << error;
  Bytes all;
  for (int i = 0; i < 50; ++i) {
    const Bytes f = xbus::MtData2(Numbered(i));
    all.insert(all.end(), f.begin(), f.end());
    ASSERT_TRUE(
        w->Append(RecordType::kReceived, 0, static_cast<std::uint64_t>(i) * 10'000'000, f, &error));
    if (i == 20) {
      const std::string e = R"({"event":"pose","index":0})";
      ASSERT_TRUE(w->Append(RecordType::kEvent, 0, 200'000'001, Bytes(e.begin(), e.end()), &error));
    }
  }
  ASSERT_TRUE(w->Close(&error));
  boost::asio::io_context io;
  auto transport = MakeTransport(io, "replay:" + path.string() + "?speed=max", 0, {}, &error);
  ASSERT_NE(transport, nullptr) << error;
  Bytes got;
  std::vector<std::pair<std::string, std::size_t>> events;  // event, bytes before it
  bool finished = false;
  transport->SetEventHandler(
      [&](const std::string& json, std::int64_t) { events.emplace_back(json, got.size()); });
  transport->Start(
      [&](std::span<const std::uint8_t> b, std::int64_t) {
        got.insert(got.end(), b.begin(), b.end());
      },
      [&](TransportStatus s, const std::string&) { finished |= s == TransportStatus::kFinished; });
  io.run_for(std::chrono::seconds(5));
  EXPECT_TRUE(finished);
  EXPECT_EQ(got, all);
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].second, 21 * xbus::MtData2(Numbered(0)).size());
  EXPECT_FALSE(MakeTransport(io, "replay:" + path.string() + "?speed=fast", 0, {}, &error));
  EXPECT_NE(error.find("speed"), std::string::npos);
  fs::remove(path);
}

TEST(Transport, BadPortsAreClearErrors) {
  boost::asio::io_context io;
  std::string error;
  EXPECT_FALSE(MakeTransport(io, "tcp://nohostport", 0, {}, &error));
  EXPECT_NE(error.find("tcp://HOST:PORT"), std::string::npos);
  EXPECT_FALSE(MakeTransport(io, "replay:/nonexistent.tcap", 0, {}, &error));
  EXPECT_FALSE(MakeTransport(io, "", 115200, {}, &error));
  // A serial port that does not exist is not an error at creation: it is retried (unplugged).
  auto t = MakeTransport(io, "/dev/ttyNONEXISTENT", 115200, {}, &error);
  ASSERT_NE(t, nullptr);
  std::string status;
  t->Start([](std::span<const std::uint8_t>, std::int64_t) {},
           [&](TransportStatus s, const std::string& m) {
             if (s == TransportStatus::kOpenFailed && status.empty()) status = m;
           });
  RunUntil(io, [&] { return !status.empty(); });
  EXPECT_NE(status.find("retrying"), std::string::npos) << status;
  t->Stop();
}

}  // namespace
}  // namespace turncal::drivers
