#include "daemon/state/journal_log.h"

#include <spdlog/pattern_formatter.h>
#include <spdlog/sinks/stdout_sinks.h>
#include <spdlog/spdlog.h>

#include <cstdlib>
#include <memory>

namespace turncal::daemon {

namespace {

class SyslogPriority final : public spdlog::custom_flag_formatter {
 public:
  void format(const spdlog::details::log_msg& msg, const std::tm&,
              spdlog::memory_buf_t& dest) override {
    char text[] = "<6>";
    switch (msg.level) {
      case spdlog::level::critical:
        text[1] = '2';
        break;
      case spdlog::level::err:
        text[1] = '3';
        break;
      case spdlog::level::warn:
        text[1] = '4';
        break;
      case spdlog::level::info:
        text[1] = '6';
        break;
      default:
        text[1] = '7';
        break;
    }
    dest.append(text, text + 3);
  }
  std::unique_ptr<custom_flag_formatter> clone() const override {
    return std::make_unique<SyslogPriority>();
  }
};

}  // namespace

void ConfigureLogging() {
  auto logger = std::make_shared<spdlog::logger>("turncald",
                                                 std::make_shared<spdlog::sinks::stderr_sink_mt>());
  if (std::getenv("JOURNAL_STREAM") != nullptr) {
    auto formatter = std::make_unique<spdlog::pattern_formatter>();
    formatter->add_flag<SyslogPriority>('*').set_pattern("%*%v");
    logger->set_formatter(std::move(formatter));
  } else {
    logger->set_pattern("[%Y-%m-%d %H:%M:%S.%e] [%l] %v");
  }
  logger->flush_on(spdlog::level::info);  // a line per event; nothing waits in a buffer
  spdlog::set_default_logger(logger);
}

}  // namespace turncal::daemon
