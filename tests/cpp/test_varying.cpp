#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <type_traits>
#include <vector>

#include "dualprobe/simulation.hpp"
#include "dualprobe/varying.hpp"

namespace {

template <typename T>
class VaryingTest : public ::testing::Test {};
using Scalars = ::testing::Types<float, double>;
TYPED_TEST_SUITE(VaryingTest, Scalars);

// Constant coefficients of the ZOH discretisation reproduce the hysteretic loop of the core.
TEST(Varying, ConstantCoefficientsAreTheHystereticLoop) {
  const double ts = 0.1;
  const std::size_t n = 4000;
  std::vector<double> gas(n);
  for (std::size_t k = 0; k < n; ++k) gas[k] = 200.0 + 80.0 * std::sin(0.004 * double(k) * k);
  const double b_heat = -std::expm1(-ts / 3.0);
  const double b_cool = -std::expm1(-ts / 5.0);
  std::vector<double> a_heat(n - 1, 1.0 - b_heat), a_cool(n - 1, 1.0 - b_cool);
  std::vector<double> f_heat(n - 1), f_cool(n - 1);
  for (std::size_t k = 0; k + 1 < n; ++k) {
    f_heat[k] = b_heat * gas[k];
    f_cool[k] = b_cool * gas[k];
  }
  std::vector<double> out(n), expected(n);
  ASSERT_EQ(dualprobe::simulate_switched_first_order(gas.data(), a_heat.data(), f_heat.data(),
                                                     a_cool.data(), f_cool.data(), n, 150.0,
                                                     out.data()),
            dualprobe::Status::ok);
  ASSERT_EQ(dualprobe::simulate_hysteretic_first_order(gas.data(), n, ts, 3.0, 5.0, 150.0,
                                                       expected.data()),
            dualprobe::Status::ok);
  // the same recursion written x + b (g - x) instead of (1 - b) x + b g: rounding only
  for (std::size_t k = 0; k < n; ++k) EXPECT_NEAR(out[k], expected[k], 1e-9) << k;
}

// A time constant that changes at one instant: each stretch is its own exponential.
TYPED_TEST(VaryingTest, PiecewiseConstantTimeConstantIsExact) {
  using S = TypeParam;
  const S ts = S(0.1);
  const std::size_t n = 201;
  std::vector<S> drive(n - 1, S(100)), a(n - 1), f(n - 1);
  for (std::size_t k = 0; k + 1 < n; ++k) {
    const S tau = k < 100 ? S(2) : S(0.5);
    a[k] = std::exp(-ts / tau);
    f[k] = (S(1) - a[k]) * drive[k];
  }
  std::vector<S> out(n);
  ASSERT_EQ(dualprobe::simulate_switched_first_order(drive.data(), a.data(), f.data(), a.data(),
                                                     f.data(), n, S(0), out.data()),
            dualprobe::Status::ok);
  const double mid = 100.0 - 100.0 * std::exp(-10.0 / 2.0);
  const double end = 100.0 - (100.0 - mid) * std::exp(-10.0 / 0.5);
  const double tol = std::is_same_v<S, float> ? 1e-3 : 1e-10;
  EXPECT_NEAR(double(out[100]), mid, tol);
  EXPECT_NEAR(double(out[200]), end, tol);
}

TEST(Varying, EmptyAndInvalid) {
  double dummy = 0.0;
  double out = -1.0;
  EXPECT_EQ(dualprobe::simulate_switched_first_order(&dummy, &dummy, &dummy, &dummy, &dummy,
                                                     std::size_t{0}, 1.0, &out),
            dualprobe::Status::ok);
  EXPECT_EQ(out, -1.0);  // nothing written
  EXPECT_EQ(dualprobe::simulate_switched_first_order(&dummy, &dummy, &dummy, &dummy, &dummy,
                                                     std::size_t{1}, 7.0, &out),
            dualprobe::Status::ok);
  EXPECT_EQ(out, 7.0);
  EXPECT_EQ(dualprobe::simulate_switched_first_order(
                &dummy, &dummy, &dummy, &dummy, &dummy, std::size_t{1},
                std::numeric_limits<double>::quiet_NaN(), &out),
            dualprobe::Status::invalid_argument);
}

}  // namespace
