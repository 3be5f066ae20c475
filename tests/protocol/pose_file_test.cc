#include "protocol/pose_file.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/frames/units.h"
#include "protocol/observability_json.h"
#include "sim/synthetic.h"

namespace turncal {
namespace {

void ExpectPose(const TablePose& p, double phi, double gamma, double psi) {
  EXPECT_NEAR(p.phi_rad, phi * kRadPerDeg, 1e-12);
  EXPECT_NEAR(p.gamma_rad, gamma * kRadPerDeg, 1e-12);
  EXPECT_NEAR(p.psi_rad, psi * kRadPerDeg, 1e-12);
}

TEST(PoseFile, CsvWithHeaderCommentsAndMixedSeparators) {
  std::vector<TablePose> poses;
  std::string error;
  ASSERT_TRUE(ParsePoses("# a comment\nphi,gamma,psi\n10,20,30\n\n  -90; 45 ;1e1\n0 0 -180\r\n",
                         &poses, &error))
      << error;
  ASSERT_EQ(poses.size(), 3u);
  ExpectPose(poses[0], 10, 20, 30);
  ExpectPose(poses[1], -90, 45, 10);
  ExpectPose(poses[2], 0, 0, -180);
}

TEST(PoseFile, JsonArraysObjectsAndWrapper) {
  std::vector<TablePose> poses;
  std::string error;
  ASSERT_TRUE(
      ParsePoses("[[1,2,3],{\"phi_deg\":4,\"gamma_deg\":5,\"psi_deg\":6},"
                 "{\"phi\":7,\"gamma\":8,\"psi\":9}]",
                 &poses, &error))
      << error;
  ASSERT_EQ(poses.size(), 3u);
  ExpectPose(poses[1], 4, 5, 6);
  ExpectPose(poses[2], 7, 8, 9);
  ASSERT_TRUE(ParsePoses(" {\"poses\": [[0, 90, 0]]}", &poses, &error)) << error;
  ASSERT_EQ(poses.size(), 1u);
  ExpectPose(poses[0], 0, 90, 0);
}

TEST(PoseFile, MalformedInputNamesWhereAndLeavesNothing) {
  std::vector<TablePose> poses;
  std::string error;
  EXPECT_FALSE(ParsePoses("phi,gamma,psi\n1,2,3\n4,5\n", &poses, &error));
  EXPECT_NE(error.find("line 3"), std::string::npos) << error;
  EXPECT_TRUE(poses.empty());
  EXPECT_FALSE(ParsePoses("1,2,3,4\n", &poses, &error));
  EXPECT_NE(error.find("line 1"), std::string::npos) << error;
  EXPECT_FALSE(ParsePoses("1,2,nan\n", &poses, &error));
  EXPECT_FALSE(ParsePoses("[[1,2,3],[1,\"x\",3]]", &poses, &error));
  EXPECT_NE(error.find("pose 1"), std::string::npos) << error;
  EXPECT_FALSE(ParsePoses("[[1,2,3]", &poses, &error));
  EXPECT_NE(error.find("JSON"), std::string::npos) << error;
  EXPECT_FALSE(ParsePoses("{\"pose\": []}", &poses, &error));
  EXPECT_FALSE(ParsePoses("# only a comment\n", &poses, &error));
  EXPECT_NE(error.find("no poses"), std::string::npos) << error;
  EXPECT_FALSE(ParsePoses("", &poses, &error));
}

TEST(ObservabilityJson, StructuralReportHasTheDocumentedShape) {
  std::string error;
  auto model = MakeModel("mag22", ModelContext{}, &error);
  std::mt19937_64 rng(1);
  const StructuralReport r =
      AnalyzeStructure(*model, GenericParameterPoint(*model, &rng), ObservabilityOptions{});
  const nlohmann::json j = ToJson(r, *model);
  EXPECT_EQ(j["model"], "mag22");
  EXPECT_EQ(j["params"], 22);
  EXPECT_EQ(j["rank"], 21);
  ASSERT_EQ(j["null_directions"].size(), 1u);
  const auto& d = j["null_directions"][0];
  ASSERT_TRUE(d.is_object());
  EXPECT_TRUE(d.contains("k11"));
  EXPECT_FALSE(d.contains("g11"));
  // The coefficients are the unit direction.
  double norm2 = 0;
  for (const auto& [name, c] : d.items()) norm2 += c.get<double>() * c.get<double>();
  EXPECT_NEAR(norm2, 1.0, 1e-6);
}

TEST(ObservabilityJson, UndeterminedSigmaIsNull) {
  std::string error;
  auto model = MakeModel("accel13", ModelContext{}, &error);
  std::vector<WeightedPose> poses;
  for (const auto& p : AboutZPoses(10))
    poses.push_back({p, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Identity(), nullptr});
  const DataReport r = AnalyzeData(*model, model->nominal(), poses, ObservabilityOptions{});
  const nlohmann::json j = ToJson(r, *model);
  EXPECT_EQ(j["rank"], 9);
  EXPECT_TRUE(j["sigma"]["bz"].is_null());
  EXPECT_FALSE(j["diversity"]["findings"].empty());
}

}  // namespace
}  // namespace turncal
