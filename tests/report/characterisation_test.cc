// The IEEE test report (report/characterisation.h): the turn-on repeatability's 95 % interval
// holds the truth in about 95 % of simulated unit histories; every item the standards ask for is
// in the report, measured or listed with why not; bad inputs are refused with a message.

#include "report/characterisation.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <string>

namespace turncal::report {
namespace {

nlohmann::json Doc(const std::string& model, double bx, double sigma,
                   const std::string& device = "imu") {
  nlohmann::json params = {{"bx", {{"value", bx}, {"sigma", sigma}}},
                           {"by", {{"value", 0.0}, {"sigma", sigma}}},
                           {"bz", {{"value", 0.0}, {"sigma", sigma}}},
                           {"Sx", {{"value", 1e-4}, {"sigma", 1e-5}}}};
  return {{"model", model}, {"device", device}, {"params", params}};
}

const CharacteristicRow* Find(const Characterisation& c, const std::string& triad,
                              const std::string& item, const std::string& axis) {
  for (const auto& r : c.rows)
    if (r.triad == triad && r.item.find(item) == 0 && r.axis == axis) return &r;
  return nullptr;
}

TEST(Characterisation, TheTurnOnRepeatabilityIntervalHoldsTheTruth) {
  // A unit switched on 6 times: its bias repeats with 1 sigma `repeat`, each session's estimate
  // has sigma `estimate`. The report's 95 % interval of the repeatability should hold `repeat` in
  // about 95 % of 400 histories (binomial 1 sigma: 1.1 %).
  const double repeat = 2e-3, estimate = 1e-3;
  std::mt19937_64 rng(5);
  std::normal_distribution<double> gauss;
  int held = 0;
  constexpr int kHistories = 400;
  for (int h = 0; h < kHistories; ++h) {
    CharacterisationInput in;
    const double b0 = 0.01 * gauss(rng);
    for (int s = 0; s < 6; ++s) {
      in.calibrations.push_back(
          Doc("accel13", b0 + repeat * gauss(rng) + estimate * gauss(rng), estimate));
      in.calibration_sources.push_back("session" + std::to_string(s));
    }
    Characterisation c;
    std::string error;
    ASSERT_TRUE(Characterise(in, &c, &error)) << error;
    const CharacteristicRow* r = Find(c, "accelerometer", "bias turn-on repeatability", "x");
    ASSERT_NE(r, nullptr);
    ASSERT_TRUE(r->has_interval);
    const double truth_mg = repeat * 1e3 / 9.80665;
    held += truth_mg >= r->low95 && truth_mg <= r->high95;
  }
  std::printf("repeatability: the 95 %% interval held the truth in %d of %d histories\n", held,
              kHistories);
  EXPECT_GE(held, 0.91 * kHistories);
  EXPECT_LE(held, 0.99 * kHistories);
}

TEST(Characterisation, EveryItemIsThereMeasuredOrWithWhyNot) {
  CharacterisationInput in;
  in.calibrations.push_back(Doc("accel13", 0.01, 1e-4));
  in.calibration_sources.push_back("imu.accel13.json");
  Characterisation c;
  std::string error;
  ASSERT_TRUE(Characterise(in, &c, &error)) << error;
  EXPECT_EQ(c.device, "imu");
  // The accelerometer's bias in mg with U = 2 sigma.
  const CharacteristicRow* bias = Find(c, "accelerometer", "bias (K0)", "x");
  ASSERT_NE(bias, nullptr);
  EXPECT_NEAR(bias->value, 0.01 * 1e3 / 9.80665, 1e-9);
  EXPECT_NEAR(bias->u95, 2 * 1e-4 * 1e3 / 9.80665, 1e-9);
  EXPECT_EQ(bias->unit, "mg");
  // What a single accel13 session cannot give is listed with the reason.
  for (const auto& [triad, item] : std::vector<std::pair<std::string, std::string>>{
           {"accelerometer", "second-order coefficient (K2)"},
           {"accelerometer", "bias turn-on repeatability"},
           {"accelerometer", "noise terms"},
           {"accelerometer", "warm-up time"},
           {"gyroscope", "bias"},
           {"gyroscope", "scale-factor non-linearity"},
           {"gyroscope", "g-sensitivity"},
           {"gyroscope", "noise terms"}}) {
    const CharacteristicRow* r = Find(c, triad, item, "");
    ASSERT_NE(r, nullptr) << triad << " " << item;
    EXPECT_FALSE(r->measured);
    EXPECT_FALSE(r->from.empty());
  }
  EXPECT_GT(c.measured(), 0);
  EXPECT_GT(c.not_measured(), 8);
  const std::string html = CharacterisationHtml(c);
  EXPECT_NE(html.find("<h2 id=\"not-measured\">"), std::string::npos);
  EXPECT_NE(html.find("second-order coefficient (K2)"), std::string::npos);
  const nlohmann::json j = ToJson(c);
  EXPECT_EQ(j["measured"].get<int>(), c.measured());
  EXPECT_EQ(j["rows"].size(), c.rows.size());
}

TEST(Characterisation, BadInputsAreRefusedWithAMessage) {
  Characterisation c;
  std::string error;
  EXPECT_FALSE(Characterise(CharacterisationInput{}, &c, &error));
  EXPECT_NE(error.find("nothing to characterise"), std::string::npos) << error;
  CharacterisationInput two;
  two.calibrations = {Doc("accel13", 0, 1e-4, "imu1"), Doc("gyro12", 0, 1e-4, "imu2")};
  two.calibration_sources = {"a.json", "b.json"};
  EXPECT_FALSE(Characterise(two, &c, &error));
  EXPECT_NE(error.find("imu2"), std::string::npos) << error;
  CharacterisationInput nomodel;
  nomodel.calibrations = {{{"device", "imu"}}};
  nomodel.calibration_sources = {"x.json"};
  EXPECT_FALSE(Characterise(nomodel, &c, &error));
  EXPECT_NE(error.find("x.json"), std::string::npos) << error;
}

}  // namespace
}  // namespace turncal::report
