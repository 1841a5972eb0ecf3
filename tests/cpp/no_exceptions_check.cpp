// Compiled with -fno-exceptions -fno-rtti: instantiates every core template the firmware uses.
#include "dualprobe/dualprobe.hpp"

namespace dualprobe {
template class DifferenceEstimator<float>;
template class DifferenceEstimator<double>;
template class InverseReconstructor<float>;
template class InverseReconstructor<double>;
template class KalmanReconstructor<float, 3>;
template class KalmanReconstructor<double, 3>;
template class KalmanReconstructor<float, 6, 16>;
template class KalmanReconstructor<double, 6, 16>;
template class KalmanReconstructor<float, 5, 1, 16, 20>;  // the ECU's, with a fixed lag
template class KalmanReconstructor<double, 5, 1, 16, 20>;
template class SvfEstimator<float, 1>;
template class SvfEstimator<double, 1>;
template class SvfEstimator<float, 1, StaticModel::affine>;
template class SvfEstimator<double, 1, StaticModel::affine>;
template class SvfEstimator<float, 2>;
template class SvfEstimator<double, 2>;
template class SvfEstimator<float, 2, StaticModel::affine>;
template class SvfEstimator<double, 2, StaticModel::affine>;
template class SvfEstimator<float, 1, StaticModel::unit, true>;
template class SvfEstimator<double, 1, StaticModel::unit, true>;
template class SvfEstimator<float, 1, StaticModel::affine, true>;
template class SvfEstimator<double, 1, StaticModel::affine, true>;
// Flow-scheduled variants (design.md 1.5): the ECU ones (Basis 1) and the largest basis.
template class SvfEstimator<float, 1, StaticModel::unit, false, 128, double, 1>;
template class SvfEstimator<float, 2, StaticModel::unit, false, 128, double, 1>;
template class SvfEstimator<float, 1, StaticModel::affine, false, 128, double, 1>;
template class SvfEstimator<float, 2, StaticModel::affine, false, 128, double, 1>;
template class SvfEstimator<float, 1, StaticModel::unit, true, 128, double, 1>;
template class SvfEstimator<double, 2, StaticModel::unit, false, 128, double, 8>;
}  // namespace dualprobe

float no_exceptions_check_entry(float t1, float t2) {
  dualprobe::DifferenceEstimator<float> estimator;
  dualprobe::DifferenceConfig<float> config;
  config.sigma1 = 0.1f;
  config.sigma2 = 0.1f;
  estimator.configure(config);
  estimator.update(t1, t2);
  return estimator.solve().tau1;
}

// The update overloads are member templates (not instantiated above): call them.
float no_exceptions_check_scheduled(float t1, float t2, float psi) {
  dualprobe::SvfScheduled<float, 1> first;
  dualprobe::SvfScheduled<float, 2> second;
  dualprobe::SvfScheduledHysteresis<float> split;
  dualprobe::SvfConfig<float> config;
  config.filter_time_constant = 2.0f;
  config.sample_interval = 0.1f;
  first.configure(config);
  second.configure(config);
  split.configure(config);
  first.update(t1, t2, psi);
  second.update(t1, t2, &psi, 1.0f / psi);
  split.update(t1, t2, psi);
  const auto moments = second.moments();
  return first.solve().theta[0] + second.solve(moments).theta[0] + split.solve().tau_heat1;
}
