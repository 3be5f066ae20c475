#pragma once
// The measurement models of MODELS.md behind one small interface.
//
// A model maps its parameter vector theta (names and order exactly as MODELS.md's table) and a
// turntable pose to the sensor's expected stationary output. Each model lives in one file under
// core/models/ (a `Def` struct plus TURNCAL_REGISTER_MODEL); the registry finds the files at
// configure time, so adding a model means adding one file.

#include <Eigen/Core>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "core/frames/reference.h"
#include "core/frames/rotations.h"
#include "core/frames/table_pose.h"
#include "core/modeling/parameter.h"

namespace ceres {
class CostFunction;
}

namespace turncal {

enum class SensorKind { kAccelerometer, kMagnetometer, kGyroscope };

// Frame of corrected live output: the orthogonal case frame r, or the table's inner frame q.
enum class OutputFrame { kCase, kTable };

const char* ToString(SensorKind kind);
const char* ToString(OutputFrame frame);

// What a model needs besides its parameters: the lab's reference vectors, the nominal mounting
// rotation M (C_q^r = C(eps) M, MODELS.md "Nominal mounting") and the wanted output frame of the
// accelerometer correction.
struct ModelContext {
  ReferenceVectors reference;
  Mat3<double> mounting = Mat3<double>::Identity();
  OutputFrame accel_output_frame = OutputFrame::kCase;

  // False with a message when the reference vectors are invalid or M is not a rotation.
  bool IsValid(std::string* error) const;
};

using Jacobian3 = Eigen::Matrix<double, 3, Eigen::Dynamic>;

class MeasurementModel {
 public:
  virtual ~MeasurementModel() = default;

  // The model's name as the CLI and JSON use it ("accel13", "mag22", ...).
  virtual const std::string& name() const = 0;
  virtual SensorKind sensor() const = 0;
  // Parameter names, kinds, units and nominal values, in MODELS.md's order.
  virtual const std::vector<ParameterInfo>& parameters() const = 0;
  virtual const ModelContext& context() const = 0;

  int num_parameters() const { return static_cast<int>(parameters().size()); }
  // Index of the parameter named `name`, or -1.
  int index_of(std::string_view name) const;
  Eigen::VectorXd nominal() const;

  // The known excitation v in NED: specific force f = -g for accelerometers, B_NED for
  // magnetometers, the Earth's rate for gyroscopes (which also see the table's rate and, through
  // their g-sensitivity, the specific force: TablePose::TableRate_q, SpecificForceNed).
  virtual Eigen::Vector3d excitation_ned() const = 0;

  // Expected stationary measurement at `pose`. theta must have num_parameters() entries.
  virtual Eigen::Vector3d Predict(const Eigen::VectorXd& theta, const TablePose& pose) const = 0;
  // Same, with the 3 x N Jacobian d(measurement)/d(theta) by automatic differentiation.
  virtual Eigen::Vector3d Predict(const Eigen::VectorXd& theta, const TablePose& pose,
                                  Jacobian3* jacobian) const = 0;

  // A gyroscope's output for any inertial rate omega_q and specific force f_q in the table's inner
  // frame (the simulator's instantaneous truth while the table moves); NaN for other sensors.
  virtual Eigen::Vector3d PredictRate(const Eigen::VectorXd& theta, const Eigen::Vector3d& omega_q,
                                      const Eigen::Vector3d& f_q) const = 0;

  // A Ceres residual r = sqrt_information * (Predict(theta, pose) - measured) over a single
  // parameter block of num_parameters() doubles. The caller owns the result (ceres::Problem
  // takes it over by default).
  virtual std::unique_ptr<ceres::CostFunction> MakeResidual(
      const TablePose& pose, const Eigen::Vector3d& measured,
      const Eigen::Matrix3d& sqrt_information) const = 0;

  // Correction of a live sample (MODELS.md "Correction of live samples"): bias removed and the
  // sensor matrix inverted, giving the specific force or field in corrected_frame().
  virtual Eigen::Vector3d Correct(const Eigen::VectorXd& theta,
                                  const Eigen::Vector3d& raw) const = 0;
  // The same with the specific force in the table frame q at the sample, which a gyroscope's
  // g-sensitivity needs (gyro21); the other models ignore it, and Correct() passes zero.
  virtual Eigen::Vector3d CorrectWithForce(const Eigen::VectorXd& theta, const Eigen::Vector3d& raw,
                                           const Eigen::Vector3d& f_q) const = 0;
  virtual OutputFrame corrected_frame() const = 0;

  // Parameters from the linear form's solution y = G C_p^q R3(beta) v + b (MODELS.md "The linear
  // form"): the physical parameters by LQ decomposition where the model has them, the rest at
  // nominal. False with a message when G cannot be decomposed (e.g. det G <= 0 for a physical
  // model: the mounting is wrong).
  virtual bool FromLinear(const Mat3<double>& G, double beta, const Eigen::Vector3d& b,
                          Eigen::VectorXd* theta, std::string* error) const = 0;

  // The seed's extended parameter vector theta^e (its eq. 11 and 28): the entries of H' (and, for
  // mag22, H'_2) row by row, then the bias. The structural observability test is the rank of
  // d(theta^e)/d(theta) (automatic differentiation, written to `jacobian` when not null).
  virtual Eigen::VectorXd Extended(const Eigen::VectorXd& theta,
                                   Eigen::MatrixXd* jacobian) const = 0;

  // Number of exact symmetries of the model that no turntable data can resolve (mag22: 2, see
  // MODELS.md "The mag22 gauge"); the calibrator fixes them with a documented gauge.
  virtual int gauge_dimension() const = 0;
};

// A model by name with the given context; nullptr with a message when the name is unknown or the
// context is invalid.
std::unique_ptr<MeasurementModel> MakeModel(std::string_view name, const ModelContext& context,
                                            std::string* error);
// Every registered model name, in a stable order.
std::vector<std::string> ModelNames();

namespace model_registry {
struct Entry {
  std::string name;
  std::function<std::unique_ptr<MeasurementModel>(const ModelContext&)> make;
};
}  // namespace model_registry

}  // namespace turncal
