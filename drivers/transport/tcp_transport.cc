// tcp://HOST:PORT: serial device servers (ser2net and similar) carry the raw byte stream.
#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/write.hpp>

#include "drivers/transport/reconnecting.h"
#include "drivers/transport/transport_impl.h"

namespace turncal::drivers {

namespace {

using Socket = boost::asio::ip::tcp::socket;

class TcpTransport final : public Reconnecting<Socket> {
 public:
  TcpTransport(boost::asio::io_context& io, std::string host, std::string port,
               TransportOptions options)
      : Reconnecting(io, options), host_(std::move(host)), port_(std::move(port)), resolver_(io) {}

  std::string Describe() const override { return "tcp://" + host_ + ":" + port_; }

  void Stop() override {
    resolver_.cancel();
    if (connecting_) {
      boost::system::error_code ignored;
      connecting_->close(ignored);
    }
    Reconnecting::Stop();
  }

 protected:
  // Resolving and connecting are asynchronous: an unreachable server never blocks the io_context.
  void BeginOpen(OpenDone done) override {
    resolver_.async_resolve(host_, port_,
                            [this, done](const boost::system::error_code& ec,
                                         boost::asio::ip::tcp::resolver::results_type endpoints) {
                              if (ec == boost::asio::error::operation_aborted) return;
                              if (ec) {
                                done(nullptr, "", "cannot resolve " + host_ + ": " + ec.message());
                                return;
                              }
                              connecting_ = std::make_unique<Socket>(io_);
                              boost::asio::async_connect(
                                  *connecting_, endpoints,
                                  [this, done](const boost::system::error_code& ec2,
                                               const boost::asio::ip::tcp::endpoint&) {
                                    if (ec2 == boost::asio::error::operation_aborted) return;
                                    if (ec2) {
                                      connecting_.reset();
                                      done(nullptr, "", "cannot connect: " + ec2.message());
                                      return;
                                    }
                                    boost::system::error_code ignored;
                                    connecting_->set_option(boost::asio::ip::tcp::no_delay(true),
                                                            ignored);
                                    done(std::move(connecting_), "TCP", "");
                                  });
                            });
  }

 private:
  std::string host_, port_;
  boost::asio::ip::tcp::resolver resolver_;
  std::unique_ptr<Socket> connecting_;
};

}  // namespace

std::unique_ptr<Transport> MakeTcpTransport(boost::asio::io_context& io, std::string host,
                                            std::string port, TransportOptions options) {
  return std::make_unique<TcpTransport>(io, std::move(host), std::move(port), options);
}

}  // namespace turncal::drivers
