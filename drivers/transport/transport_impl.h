#pragma once
// Private: the transport implementations behind MakeTransport.

#include <memory>
#include <string>

#include "drivers/transport/transport.h"

namespace turncal::drivers {

std::unique_ptr<Transport> MakeSerialTransport(boost::asio::io_context& io, std::string path,
                                               int baud, TransportOptions options);
std::unique_ptr<Transport> MakeTcpTransport(boost::asio::io_context& io, std::string host,
                                            std::string port, TransportOptions options);
std::unique_ptr<Transport> MakeReplayTransport(boost::asio::io_context& io, std::string file,
                                               double speed, std::string* error);

}  // namespace turncal::drivers
