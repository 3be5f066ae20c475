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
      : Reconnecting(io, options), host_(std::move(host)), port_(std::move(port)) {}

  std::string Describe() const override { return "tcp://" + host_ + ":" + port_; }

 protected:
  bool OpenStream(std::unique_ptr<Socket>* stream, std::string* how, std::string* error) override {
    boost::system::error_code ec;
    boost::asio::ip::tcp::resolver resolver(io_);
    const auto endpoints = resolver.resolve(host_, port_, ec);
    if (ec) {
      *error = "cannot resolve " + host_ + ": " + ec.message();
      return false;
    }
    auto socket = std::make_unique<Socket>(io_);
    boost::asio::connect(*socket, endpoints, ec);
    if (ec) {
      *error = "cannot connect: " + ec.message();
      return false;
    }
    socket->set_option(boost::asio::ip::tcp::no_delay(true), ec);
    *stream = std::move(socket);
    *how = "TCP";
    return true;
  }

 private:
  std::string host_, port_;
};

}  // namespace

std::unique_ptr<Transport> MakeTcpTransport(boost::asio::io_context& io, std::string host,
                                            std::string port, TransportOptions options) {
  return std::make_unique<TcpTransport>(io, std::move(host), std::move(port), options);
}

}  // namespace turncal::drivers
