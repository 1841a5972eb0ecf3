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
