// Serial ports: libserialport for real hardware; termios for pseudo-terminals, which have no
// sysfs entry and which libserialport therefore cannot open. The file descriptor is driven by a
// Boost.Asio stream_descriptor: reads never block.
#include <fcntl.h>
#include <libserialport.h>
#include <sys/file.h>
#include <termios.h>
#include <unistd.h>

#include <boost/asio/posix/stream_descriptor.hpp>
#include <boost/asio/write.hpp>
#include <cerrno>
#include <cstring>

#include "drivers/transport/reconnecting.h"
#include "drivers/transport/transport_impl.h"

namespace turncal::drivers {

namespace {

using Descriptor = boost::asio::posix::stream_descriptor;

speed_t TermiosSpeed(int baud) {
  switch (baud) {
    case 9600:
      return B9600;
    case 19200:
      return B19200;
    case 38400:
      return B38400;
    case 57600:
      return B57600;
    case 115200:
      return B115200;
    case 230400:
      return B230400;
    case 460800:
      return B460800;
    case 921600:
      return B921600;
    default:
      return B0;
  }
}

class SerialTransport final : public Reconnecting<Descriptor> {
 public:
  SerialTransport(boost::asio::io_context& io, std::string path, int baud, TransportOptions options)
      : Reconnecting(io, options), path_(std::move(path)), baud_(baud) {}
  ~SerialTransport() override { CloseExtra(); }

  std::string Describe() const override { return fmt::format("serial {}@{}", path_, baud_); }

 protected:
  // Device files open at once: synchronously.
  void BeginOpen(OpenDone done) override {
    std::unique_ptr<Descriptor> stream;
    std::string how, error;
    if (!OpenStream(&stream, &how, &error)) stream.reset();
    done(std::move(stream), how, error);
  }

  bool OpenStream(std::unique_ptr<Descriptor>* stream, std::string* how, std::string* error) {
    int fd = -1;
    std::string sp_error;
    if (OpenWithLibserialport(&fd, &sp_error)) {
      *how = "libserialport";
    } else if (OpenWithTermios(&fd, error)) {
      *how = "termios, a pseudo-terminal or a port libserialport cannot open (" + sp_error + ")";
    } else {
      *error = sp_error + "; termios: " + *error;
      return false;
    }
    *stream = std::make_unique<Descriptor>(io_, fd);
    return true;
  }

  void CloseExtra() override {
    if (port_) {
      sp_close(port_);
      sp_free_port(port_);
      port_ = nullptr;
    }
  }

 private:
  bool OpenWithLibserialport(int* fd, std::string* error) {
    sp_port* port = nullptr;
    if (sp_get_port_by_name(path_.c_str(), &port) != SP_OK) {
      *error = "libserialport does not know " + path_;
      return false;
    }
    auto fail = [&](const char* what) {
      char* message = sp_last_error_message();
      *error = fmt::format("libserialport: {}: {}", what, message ? message : "?");
      sp_free_error_message(message);
      sp_close(port);
      sp_free_port(port);
      return false;
    };
    if (sp_open(port, SP_MODE_READ_WRITE) != SP_OK) return fail("open");
    if (sp_set_baudrate(port, baud_) != SP_OK || sp_set_bits(port, 8) != SP_OK ||
        sp_set_parity(port, SP_PARITY_NONE) != SP_OK ||
        sp_set_stopbits(port, options_.two_stop_bits ? 2 : 1) != SP_OK ||
        sp_set_flowcontrol(port, SP_FLOWCONTROL_NONE) != SP_OK) {
      return fail("configure");
    }
    int handle = -1;
    if (sp_get_port_handle(port, &handle) != SP_OK) return fail("handle");
    if (::flock(handle, LOCK_EX | LOCK_NB) != 0) {
      *error = path_ + " is in use by another process";
      sp_close(port);
      sp_free_port(port);
      return false;
    }
    const int dup =
        ::fcntl(handle, F_DUPFD_CLOEXEC, 0);  // Asio owns this one; libserialport keeps its own
    if (dup < 0) return fail("dup");
    ::fcntl(dup, F_SETFL, ::fcntl(dup, F_GETFL) | O_NONBLOCK);
    port_ = port;
    *fd = dup;
    return true;
  }

  bool OpenWithTermios(int* fd_out, std::string* error) {
    const int fd = ::open(path_.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0) {
      *error = fmt::format("cannot open {}: {}", path_, std::strerror(errno));
      return false;
    }
    if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
      *error = path_ + " is in use by another process";
      ::close(fd);
      return false;
    }
    termios t{};
    if (::tcgetattr(fd, &t) != 0) {
      *error = fmt::format("{} is not a terminal: {}", path_, std::strerror(errno));
      ::close(fd);
      return false;
    }
    ::cfmakeraw(&t);
    t.c_cflag |= CLOCAL | CREAD;
    if (options_.two_stop_bits) t.c_cflag |= CSTOPB;
    const speed_t speed = TermiosSpeed(baud_);
    if (speed == B0) {
      *error = fmt::format("{} baud is not a termios speed (9600 ... 921600)", baud_);
      ::close(fd);
      return false;
    }
    ::cfsetispeed(&t, speed);
    ::cfsetospeed(&t, speed);
    if (::tcsetattr(fd, TCSANOW, &t) != 0) {
      *error = fmt::format("cannot configure {}: {}", path_, std::strerror(errno));
      ::close(fd);
      return false;
    }
    *fd_out = fd;
    return true;
  }

  std::string path_;
  int baud_;
  sp_port* port_ = nullptr;
};

}  // namespace

std::unique_ptr<Transport> MakeSerialTransport(boost::asio::io_context& io, std::string path,
                                               int baud, TransportOptions options) {
  return std::make_unique<SerialTransport>(io, std::move(path), baud, options);
}

}  // namespace turncal::drivers
