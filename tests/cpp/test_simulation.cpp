#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "dualprobe/simulation.hpp"

namespace {

TEST(Simulation, HystereticSensorHeatsAndCoolsWithItsOwnTimeConstants) {
  const double ts = 0.1;
  const std::size_t n = 6000;
  std::vector<double> gas(n, 100.0);
  for (std::size_t k = 3000; k < n; ++k) gas[k] = 20.0;
  std::vector<double> out(n);
  ASSERT_EQ(dualprobe::simulate_hysteretic_first_order(gas.data(), n, ts, 21.96, 28.86, 20.0,
                                                       out.data()),
            dualprobe::Status::ok);
  // Heating from 20 towards 100 starting at k = 0; cooling from out[3000] towards 20.
  const double heat_expected = 100.0 - 80.0 * std::exp(-1000 * ts / 21.96);
  EXPECT_NEAR(out[1000], heat_expected, 1e-9);
  const double start = out[3000];
  const double cool_expected = 20.0 + (start - 20.0) * std::exp(-1000 * ts / 28.86);
  EXPECT_NEAR(out[4000], cool_expected, 1e-9);
}

TEST(Simulation, RejectsBadArguments) {
  double gas = 1.0;
  double out = 0.0;
  EXPECT_EQ(dualprobe::simulate_hysteretic_first_order(&gas, 1, 0.1, -1.0, 2.0, 0.0, &out),
            dualprobe::Status::invalid_argument);
}

}  // namespace
