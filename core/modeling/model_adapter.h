#pragma once
// Turns a model definition (a struct in one file of core/models/) into a MeasurementModel.
//
// A definition `Def` provides:
//   static constexpr std::string_view kName;   static constexpr int kNumParams;
//   static constexpr SensorKind kSensor;
//   static std::vector<ParameterInfo> Parameters(const ModelContext&);
//   template <typename T>
//   static Vec3<T> Predict(const T* theta, const Mat3<T>& C_p_q, const Vec3<T>& v_ned,
//                          const ModelContext&);
//   static Eigen::Vector3d Correct(const double* theta, const Eigen::Vector3d& raw,
//                                  const ModelContext&);
// A gyroscope's definition (kSensor == kGyroscope) provides instead
//   template <typename T>
//   static Vec3<T> PredictRate(const T* theta, const Vec3<T>& omega_q, const Vec3<T>& f_q,
//                              const ModelContext&);
//   static Eigen::Vector3d Correct(const double* theta, const Eigen::Vector3d& raw,
//                                  const Eigen::Vector3d& f_q, const ModelContext&);
// and sees, for a pose, omega_q = MeanC_p_q() (Earth's rate in NED) + TableRate_q() and
// f_q = MeanC_p_q() f_NED (the means over a rate segment's whole revolutions).
//   static OutputFrame CorrectedFrame(const ModelContext&);
//   static bool FromLinear(const Mat3<double>& G, double beta, const Eigen::Vector3d& b,
//                          const ModelContext&, double* theta, std::string* error);
//   template <typename T>
//   static void Extended(const T* theta, const ModelContext&, std::vector<T>* theta_e);
// and optionally `static constexpr int kGaugeDimension` (0 when absent),
// and registers itself with TURNCAL_REGISTER_MODEL(file_stem, Def).

#include <ceres/autodiff_cost_function.h>
#include <ceres/jet.h>

#include <cassert>
#include <limits>
#include <vector>

#include "core/modeling/measurement_model.h"

namespace turncal {

template <class Def>
class ModelAdapter final : public MeasurementModel {
 public:
  static constexpr int N = Def::kNumParams;

  static constexpr bool kGyro = Def::kSensor == SensorKind::kGyroscope;

  explicit ModelAdapter(const ModelContext& context)
      : context_(context),
        name_(Def::kName),
        parameters_(Def::Parameters(context)),
        excitation_ned_(Excitation(context)),
        f_ned_(SpecificForceNed(context.reference)) {
    assert(static_cast<int>(parameters_.size()) == N);
  }

  const std::string& name() const override { return name_; }
  SensorKind sensor() const override { return Def::kSensor; }
  const std::vector<ParameterInfo>& parameters() const override { return parameters_; }
  const ModelContext& context() const override { return context_; }
  Eigen::Vector3d excitation_ned() const override { return excitation_ned_; }

  Eigen::Vector3d Predict(const Eigen::VectorXd& theta, const TablePose& pose) const override {
    assert(theta.size() == N);
    return Stimulus::Of(pose, *this).template Predict<double>(theta.data(), context_);
  }

  Eigen::Vector3d Predict(const Eigen::VectorXd& theta, const TablePose& pose,
                          Jacobian3* jacobian) const override {
    assert(theta.size() == N);
    if (jacobian == nullptr) return Predict(theta, pose);
    using Jet = ceres::Jet<double, N>;
    Jet theta_jet[N];
    for (int i = 0; i < N; ++i) theta_jet[i] = Jet(theta[i], i);
    const Vec3<Jet> y = Stimulus::Of(pose, *this).template Predict<Jet>(theta_jet, context_);
    jacobian->resize(3, N);
    Eigen::Vector3d value;
    for (int r = 0; r < 3; ++r) {
      value[r] = y[r].a;
      jacobian->row(r) = y[r].v.transpose();
    }
    return value;
  }

  Eigen::Vector3d PredictRate(const Eigen::VectorXd& theta, const Eigen::Vector3d& omega_q,
                              const Eigen::Vector3d& f_q) const override {
    assert(theta.size() == N);
    if constexpr (kGyro) {
      return Def::template PredictRate<double>(theta.data(), omega_q, f_q, context_);
    } else {
      return Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
    }
  }

  std::unique_ptr<ceres::CostFunction> MakeResidual(
      const TablePose& pose, const Eigen::Vector3d& measured,
      const Eigen::Matrix3d& sqrt_information) const override {
    return std::make_unique<ceres::AutoDiffCostFunction<Residual, 3, N>>(
        new Residual{Stimulus::Of(pose, *this), measured, sqrt_information, &context_});
  }

  Eigen::Vector3d Correct(const Eigen::VectorXd& theta, const Eigen::Vector3d& raw) const override {
    return CorrectWithForce(theta, raw, Eigen::Vector3d::Zero());
  }
  Eigen::Vector3d CorrectWithForce(const Eigen::VectorXd& theta, const Eigen::Vector3d& raw,
                                   const Eigen::Vector3d& f_q) const override {
    assert(theta.size() == N);
    if constexpr (kGyro) {
      return Def::Correct(theta.data(), raw, f_q, context_);
    } else {
      return Def::Correct(theta.data(), raw, context_);
    }
  }
  OutputFrame corrected_frame() const override { return Def::CorrectedFrame(context_); }

  bool FromLinear(const Mat3<double>& G, double beta, const Eigen::Vector3d& b,
                  Eigen::VectorXd* theta, std::string* error) const override {
    theta->resize(N);
    return Def::FromLinear(G, beta, b, context_, theta->data(), error);
  }

  Eigen::VectorXd Extended(const Eigen::VectorXd& theta, Eigen::MatrixXd* jacobian) const override {
    assert(theta.size() == N);
    using Jet = ceres::Jet<double, N>;
    Jet theta_jet[N];
    for (int i = 0; i < N; ++i) theta_jet[i] = Jet(theta[i], i);
    std::vector<Jet> theta_e;
    Def::template Extended<Jet>(theta_jet, context_, &theta_e);
    const auto M = static_cast<Eigen::Index>(theta_e.size());
    Eigen::VectorXd value(M);
    if (jacobian) jacobian->resize(M, N);
    for (Eigen::Index r = 0; r < M; ++r) {
      value[r] = theta_e[r].a;
      if (jacobian) jacobian->row(r) = theta_e[r].v.transpose();
    }
    return value;
  }

  int gauge_dimension() const override {
    if constexpr (requires { Def::kGaugeDimension; }) {
      return Def::kGaugeDimension;
    } else {
      return 0;
    }
  }

 private:
  static Eigen::Vector3d Excitation(const ModelContext& context) {
    switch (Def::kSensor) {
      case SensorKind::kAccelerometer:
        return SpecificForceNed(context.reference);
      case SensorKind::kMagnetometer:
        return context.reference.B_ned;
      case SensorKind::kGyroscope:
        return EarthRateNed(context.reference);
    }
    return Eigen::Vector3d::Zero();
  }

  // What a pose excites: C_p^q and v_NED for an accelerometer or magnetometer; the inertial rate
  // and the specific force in q for a gyroscope.
  struct Stimulus {
    Mat3<double> C_p_q;
    Eigen::Vector3d v_ned;
    Eigen::Vector3d omega_q, f_q;

    static Stimulus Of(const TablePose& pose, const ModelAdapter& m) {
      Stimulus s;
      if constexpr (kGyro) {
        const Mat3<double> C = pose.MeanC_p_q();
        s.omega_q = C * m.excitation_ned_ + pose.TableRate_q();
        s.f_q = C * m.f_ned_;
      } else {
        s.C_p_q = pose.C_p_q();
        s.v_ned = m.excitation_ned_;
      }
      return s;
    }
    template <typename T>
    Vec3<T> Predict(const T* theta, const ModelContext& context) const {
      if constexpr (kGyro) {
        return Def::template PredictRate<T>(theta, omega_q.cast<T>(), f_q.cast<T>(), context);
      } else {
        return Def::template Predict<T>(theta, C_p_q.cast<T>(), v_ned.cast<T>(), context);
      }
    }
  };

  // The residual functor keeps a pointer to the model's context: a cost function must not outlive
  // the model that made it.
  struct Residual {
    Stimulus stimulus;
    Eigen::Vector3d measured;
    Eigen::Matrix3d sqrt_information;
    const ModelContext* context;

    template <typename T>
    bool operator()(const T* theta, T* residual) const {
      const Vec3<T> y = stimulus.template Predict<T>(theta, *context);
      Eigen::Map<Vec3<T>> r(residual);
      r = sqrt_information.cast<T>() * (y - measured.cast<T>());
      return true;
    }
  };

  ModelContext context_;
  std::string name_;
  std::vector<ParameterInfo> parameters_;
  Eigen::Vector3d excitation_ned_;
  Eigen::Vector3d f_ned_;  // the specific force, which a gyroscope's g-sensitivity sees
};

}  // namespace turncal

// Registers model definition `Def` from the file core/models/<stem>.cc. The registry
// (core/modeling/measurement_model.cc) calls one function per file, generated by CMake from the
// file names.
#define TURNCAL_REGISTER_MODEL(stem, Def)                                                    \
  namespace turncal::model_registry {                                                        \
  Entry Entry_##stem() {                                                                     \
    return Entry{std::string(Def::kName), [](const ModelContext& context) {                  \
                   return std::unique_ptr<MeasurementModel>(new ModelAdapter<Def>(context)); \
                 }};                                                                         \
  }                                                                                          \
  }
