#pragma once
// Has a climate chamber's soak settled (issue 36)? While the controller has announced a chamber
// set-point (`{"cmd":"chamber","setpoint_c":...}`, docs/protocol.md), a pose waits until the
// sensor's own temperature has stopped moving: its slope over the last `window_s` (a least-squares
// line through the reported temperature) below `max_rate_c_per_min`. The die follows the air with
// a lag of minutes and may settle away from the set-point (self-heating, a chamber that cannot
// reach it): what counts is that it stopped moving, and the waiting reason says how far it is from
// the set-point. Poses during a ramp (no set-point announced) are taken at once, each with the
// temperature it was taken at.

#include <cstddef>
#include <deque>
#include <optional>
#include <string>

namespace turncal {

struct SoakOptions {
  double setpoint_c = 25.0;
  double max_rate_c_per_min = 0.05;
  double window_s = 60.0;
  // A pose that waits longer for the soak is rejected with the soak's state as the reason.
  double timeout_s = 3600.0;
  // Once the temperature has settled, the bias too (core/sequencing/bias_settle.h): the table at
  // rest for the window, its output's two halves agreeing; checked once per set-point.
  bool check_bias = true;

  bool IsValid(std::string* error) const;
};

class SoakTracker {
 public:
  // One temperature reading (sensor or host seconds, increasing); readings closer than a tenth
  // of a second to the previous one kept are skipped, those older than the window dropped.
  void Add(double t_s, double temp_c, double window_s);
  void Clear() { points_.clear(); }
  // The slope over the window, degC/min (nullopt before the readings span 80 % of it).
  std::optional<double> RateCPerMin(double window_s) const;
  std::optional<double> latest_c() const;
  // Settled, or why not ("the sensor's temperature 33.20 degC moves 0.31 degC/min (settled below
  // 0.05 over 60 s); the set-point is 40.0 degC").
  bool Settled(const SoakOptions& soak, std::string* why) const;

 private:
  struct Point {
    double t_s, temp_c;
  };
  std::deque<Point> points_;
};

}  // namespace turncal
