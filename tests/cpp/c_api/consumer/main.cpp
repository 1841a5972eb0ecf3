// C++ consumer of the installed header-only dualprobe::core.
#include <cmath>
#include <cstdio>

#include "dualprobe/dualprobe.hpp"

int main() {
  dualprobe::DifferenceEstimator<double> estimator;
  dualprobe::DifferenceConfig<double> config;
  config.sample_interval = 1.0;
  config.method = dualprobe::Method::ls;
  if (estimator.configure(config) != dualprobe::Status::ok) return 1;
  dualprobe::FirstOrderSensor<double> s1, s2;
  s1.set_time_constant(5.0, 1.0);
  s2.set_time_constant(15.0, 1.0);
  double t1 = 0.0, t2 = 0.0;
  for (int k = 0; k < 400; ++k) {
    const double gas = (k / 40) % 2 == 0 ? 10.0 : -10.0;
    estimator.update(t1, t2);
    t1 = s1.step(t1, gas);
    t2 = s2.step(t2, gas);
  }
  const auto result = estimator.solve();
  std::printf("consumer_cpp: %s tau1=%.9f tau2=%.9f\n", dualprobe::to_string(result.status),
              result.tau1, result.tau2);
  // Noise-free double data from the exact model: 1e-6 relative.
  return result.status == dualprobe::Status::ok && std::abs(result.tau1 / 5.0 - 1.0) < 1e-6 &&
                 std::abs(result.tau2 / 15.0 - 1.0) < 1e-6
             ? 0
             : 1;
}
