#include <gtest/gtest.h>

#include <cmath>

#include "dualprobe/first_order.hpp"

namespace {

template <typename T>
class FirstOrderTest : public ::testing::Test {};
using Scalars = ::testing::Types<float, double>;
TYPED_TEST_SUITE(FirstOrderTest, Scalars);

TYPED_TEST(FirstOrderTest, CoefficientsMatchEquationNine) {
  using S = TypeParam;
  dualprobe::FirstOrderSensor<S> sensor;
  ASSERT_TRUE(sensor.set_time_constant(S(12.48), S(0.1)));
  EXPECT_NEAR(double(sensor.a), std::exp(-0.1 / 12.48), 1e-6);
  EXPECT_NEAR(double(sensor.a + sensor.b), 1.0, 1e-7);
  const S tau = dualprobe::FirstOrderSensor<S>::time_constant_from_b(sensor.b, S(0.1));
  // float: b ~ 8e-3 carries ~1e-7 relative rounding, amplified ~1x through log1p.
  EXPECT_NEAR(double(tau), 12.48, 12.48 * (sizeof(S) == 4 ? 1e-5 : 1e-12));
}

TYPED_TEST(FirstOrderTest, InverseUndoesStep) {
  using S = TypeParam;
  dualprobe::FirstOrderSensor<S> sensor;
  ASSERT_TRUE(sensor.set_time_constant(S(2), S(0.5)));
  const S previous = S(20);
  const S gas = S(180);
  const S next = sensor.step(previous, gas);
  EXPECT_NEAR(double(sensor.inverse(next, previous)), 180.0, sizeof(S) == 4 ? 1e-3 : 1e-11);
}

TYPED_TEST(FirstOrderTest, RejectsNonPhysicalTimeConstant) {
  using S = TypeParam;
  dualprobe::FirstOrderSensor<S> sensor;
  const auto before_a = sensor.a;
  EXPECT_FALSE(sensor.set_time_constant(S(0), S(1)));
  EXPECT_FALSE(sensor.set_time_constant(S(-1), S(1)));
  EXPECT_FALSE(sensor.set_time_constant(S(1), std::numeric_limits<S>::quiet_NaN()));
  EXPECT_EQ(sensor.a, before_a);
}

}  // namespace
