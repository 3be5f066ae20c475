#pragma once
// A sensor axis at rest with the IEEE Std 952-2020 noise terms as its truth (issue 39 item 5):
// quantisation Q (a uniform angle error of standard deviation Q, differenced), white rate N,
// flicker rate B (a sum of first-order Gauss-Markov processes, three a decade, whose spectra
// add up to B^2 / (2 pi f) from a thirtieth of a sample period to a hundred recording lengths,
// each averaged over the sample interval as a sensor's output is; its Allan variance is IEEE's
// within 1.5 % from five samples to a third of the recording), a rate random walk K
// and a rate ramp R, on top of a turn-on bias drawn per run (the repeatability). The Allan
// variance of what it draws is core/analysis/ieee_noise.h's model. Simulation only.

#include <array>
#include <cstdint>
#include <random>
#include <vector>

#include "core/analysis/ieee_noise.h"

namespace turncal::sim {

struct NoiseTerms {
  double q = 0.0;             // unit * s (angle / velocity)
  double n = 0.0;             // unit / sqrt(Hz)
  double b = 0.0;             // unit
  double k = 0.0;             // unit / sqrt(s)
  double r = 0.0;             // unit / s
  double turn_on_bias = 0.0;  // 1 sigma of the bias drawn at each turn-on, unit
  std::array<double, 5> AsArray() const { return {q, n, b, k, r}; }
};

// The flicker's Gauss-Markov processes: correlation time and stationary variance of each.
// (core/analysis/ieee_noise.h's, from a thirtieth of the sample period to 100 spans).
using FlickerPole = GaussMarkovPole;
std::vector<FlickerPole> FlickerPoles(double b, double dt_s, double span_s);

class NoiseTermsGenerator {
 public:
  // Samples dt_s apart over about `span_s` (the flicker's longest correlation time is a
  // hundred times it).
  NoiseTermsGenerator(const NoiseTerms& terms, double dt_s, double span_s, std::uint64_t seed);
  double Next();  // the next sample
  double turn_on_bias() const { return bias_; }

 private:
  NoiseTerms terms_;
  double dt_s_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> gauss_{0.0, 1.0};
  std::uniform_real_distribution<double> uniform_{-0.5, 0.5};
  double bias_ = 0.0, walk_ = 0.0, angle_error_ = 0.0, t_s_ = 0.0;
  struct Pole {
    double phi = 0.0, mean_integral = 0.0, l11 = 0.0, l21 = 0.0, l22 = 0.0, x = 0.0;
  };
  std::vector<Pole> poles_;
};

}  // namespace turncal::sim
