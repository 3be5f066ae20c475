#pragma once
// The models of a calibration without known poses (issue 22, "free mode"): a tumble by hand or on
// a fixture with unknown angles. The data are the static intervals the sequencer found (pose
// records whose pose is not known) and the moves between them; what is known is only that the
// specific force's magnitude is the local gravity, the field's magnitude is constant (and is the
// reference's when given), the angle between the two (the dip) is constant, and the gyro's turn
// between two intervals carries gravity's direction from the one to the other.
//
// A free model maps the intervals to residual terms, each a Ceres cost over the model's parameter
// block (and, for a model built on another's estimate such as gyro9 on accel9, that estimate's
// block after it), whitened by the covariance of the interval means the term uses at a given
// parameter point, so the sum of squares is a chi^2 and its Hessian the Fisher information
// (core/estimation/free_calibrator.h re-whitens at the solution). Each model is one file in
// core/models/ registering itself with TURNCAL_REGISTER_FREE_MODEL.

#include <ceres/cost_function.h>

#include <Eigen/Core>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "core/estimation/bias_drift.h"
#include "core/estimation/pose_record.h"
#include "core/modeling/measurement_model.h"
#include "core/modeling/parameter.h"

namespace turncal {

struct FreeContext {
  // The local gravity's magnitude, m/s^2 (|g_NED| of [reference]).
  double gravity_mps2 = 9.80665;
  // The field's magnitude in the magnetometer's unit; 0 when not known: the magnetometer models
  // then fix it at 1, so their scale is only relative (the report says so).
  double field_magnitude = 0.0;
  // The Earth's rate, rad/s, which a gyroscope at rest sees in an unknown direction (its vertical
  // part is known from gravity only with the latitude).
  double earth_rate_radps = kEarthRate_radps;
  double latitude_deg = 45.0;
  // The field's dip below the horizontal, degrees (from [reference]'s B_NED), for the advice on
  // which orientation to add; the joint model estimates its own.
  double dip_deg = 60.0;
  // Variance added to each interval's mean on every axis for what one interval's averaging does
  // not see (a hand's placement, anything independent from one interval to the next), triad
  // units.
  double acc_offset_sigma = 0.0;
  double mag_offset_sigma = 0.0;
  double gyr_offset_sigma = 0.0;
  // Each triad's bias drift as a process in time (core/estimation/bias_drift.h; disabled by
  // default). When enabled, the calibrator correlates every term through it -- the intervals'
  // means and, for the gyro, the moves' integrals -- by generalised least squares, and the bias
  // parameters are the bias over the latest interval (FreeEstimate::bias_window).
  BiasDrift acc_drift, mag_drift, gyr_drift;

  bool IsValid(std::string* error) const;
};

// One static interval: its triads' statistics, time window and the move that led to it (the
// sequencer's PoseRecord with its pose left unknown).
using FreeInterval = PoseRecord;

struct FreeData {
  std::vector<FreeInterval> intervals;  // in time order
  FreeContext context;
  // The estimate of the model this one builds on (gyro9: accel9's parameters and covariance);
  // empty when it builds on none.
  Eigen::VectorXd upstream_theta;
  Eigen::MatrixXd upstream_covariance;
};

// The covariance of a triad's mean over an interval: the record's batch-means estimate when it has
// one, else the sample covariance over the count; plus `offset_sigma`^2 on each axis.
Eigen::Matrix3d MeanCovariance(const TriadStats& stats, double offset_sigma);

struct FreeTerm {
  // Over the model's parameter block, then (when `upstream`) the upstream model's.
  std::unique_ptr<ceres::CostFunction> cost;
  bool upstream = false;
  int interval = -1;  // the interval it belongs to (a move's: its destination)
  std::string kind;   // "norm", "direction", "rest", "dip"
  // The time it averages over on the sensor's clock (an interval's window, a move's span): the
  // bias drift of the triads whose bias the model carries (FreeModel::BiasColumns) correlates
  // terms through it.
  TimeWindow window;
  // Other triads' readings the term depends on over other windows, with the (whitened) residual's
  // sensitivity to an offset of each (rows: the residuals, 3 columns): gyro9's direction term and
  // the accelerometer at both of its ends, whose drift moves gravity's measured direction.
  struct DriftInput {
    SensorKind triad = SensorKind::kAccelerometer;
    TimeWindow window;
    Eigen::MatrixXd sensitivity;
  };
  std::vector<DriftInput> extra_drift;
  // Random vectors several terms share, one per key, zero-mean with `covariance`, and the
  // (whitened) residual's sensitivity to it: the Earth's horizontal rate in an interval's frame,
  // which its rest and the move into it both see (its direction is the unknown heading).
  struct SharedNoise {
    int key = -1;
    Eigen::MatrixXd sensitivity;  // rows: the residuals, 3 columns
    Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  };
  std::vector<SharedNoise> shared;
};

class FreeModel {
 public:
  virtual ~FreeModel() = default;
  virtual const std::string& name() const = 0;
  // One line for `turncal models` and the report.
  virtual std::string description() const = 0;
  // The triad it calibrates (the joint model's: the magnetometer) and the triads its intervals
  // must carry.
  virtual SensorKind sensor() const = 0;
  virtual bool Needs(SensorKind triad) const = 0;
  // The model whose estimate it builds on ("accel9" for gyro9), or empty.
  virtual std::string upstream() const { return {}; }
  virtual const std::vector<ParameterInfo>& parameters() const = 0;
  int num_parameters() const { return static_cast<int>(parameters().size()); }
  // Where each triad's bias (three parameters, x y z) starts in theta. A term's sensitivity to an
  // offset of that triad's raw reading is minus its sensitivity to the bias, which the drift's
  // generalised least squares uses.
  virtual std::vector<std::pair<SensorKind, int>> BiasColumns() const = 0;
  int index_of(std::string_view name) const;

  // The sizes the rank test scales the columns by at theta (1 for gains and angles, the
  // excitation's magnitude in the triad's unit for biases).
  virtual Eigen::VectorXd Scales(const FreeData& data, const Eigen::VectorXd& theta) const = 0;
  // A start from the intervals alone (an algebraic fit where the model has one, else nominal).
  // False with a message when there are too few intervals for any start.
  virtual bool Start(const FreeData& data, Eigen::VectorXd* theta, std::string* error) const = 0;
  // The residual terms, whitened at theta.
  virtual std::vector<FreeTerm> Terms(const FreeData& data, const Eigen::VectorXd& theta) const = 0;
  // A raw sample of the calibrated triad corrected: the specific force, rate or field (the
  // magnetometer's in the field's unit, or relative when its magnitude is not known).
  virtual Eigen::Vector3d Correct(const Eigen::VectorXd& theta,
                                  const Eigen::Vector3d& raw) const = 0;
  // What the calibration leaves at theta, in the quantity's own unit, for figures a user can
  // compare with other tools: per interval (or move) a kind ("norm": |x| - magnitude in the
  // triad's unit; "direction": the angle, rad, between gravity's direction and the one the gyro
  // carried it to; "dip": the angle's deviation, rad) and the value.
  struct Misfit {
    std::string kind;
    int interval = -1;
    double value = 0.0;
  };
  virtual std::vector<Misfit> Misfits(const FreeData& data, const Eigen::VectorXd& theta) const = 0;
  // The parameters that leave the raw triad as it is (gains 1, angles and biases 0): "before".
  virtual Eigen::VectorXd Identity(const FreeData& data) const = 0;
  // The triad's mean over `interval` corrected, whose direction the coverage counts (the
  // gyroscope's: the specific force's, for which it has the upstream's parameters).
  virtual Eigen::Vector3d Direction(const FreeData& data, const Eigen::VectorXd& theta,
                                    const FreeInterval& interval) const = 0;
};

std::unique_ptr<FreeModel> MakeFreeModel(std::string_view name, const FreeContext& context,
                                         std::string* error);
std::vector<std::string> FreeModelNames();

namespace model_registry {
struct FreeEntry {
  std::string name;
  std::function<std::unique_ptr<FreeModel>(const FreeContext&)> make;
};
}  // namespace model_registry

#define TURNCAL_REGISTER_FREE_MODEL(stem, Class)                              \
  namespace turncal::model_registry {                                         \
  FreeEntry FreeEntry_##stem() {                                              \
    return FreeEntry{#stem, [](const FreeContext& context) {                  \
                       return std::unique_ptr<FreeModel>(new Class(context)); \
                     }};                                                      \
  }                                                                           \
  }

}  // namespace turncal
