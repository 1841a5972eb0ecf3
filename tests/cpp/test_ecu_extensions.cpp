// Core additions for the ECU loop (issue 13), float and double:
//  * SvfEstimator::break_chain: a gap in the samples keeps the accumulated estimate and the
//    rows while the cascade transient decays are skipped;
//  * KalmanReconstructor::set_model: the per-interval model of a flow schedule.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "dualprobe/kalman.hpp"
#include "dualprobe/svf_estimator.hpp"
#include "test_support.hpp"

namespace {

template <typename T>
class EcuExtensions : public ::testing::Test {};
using Scalars = ::testing::Types<float, double>;
TYPED_TEST_SUITE(EcuExtensions, Scalars);

// Noise-free first-order pair (difference-equation data, exact for the ZOH model) at 100 Hz
// with a 300-sample gap. tf = 0.6 s. Truth 1.248 / 2.895 s.
template <typename S>
typename dualprobe::SvfFirstOrder<S>::Result run_with_gap(bool use_break) {
  const auto series = dualprobe::test::difference_equation_pair(30000, 1.248, 2.895, 0.01, 7u, 150);
  dualprobe::SvfFirstOrder<S> svf;
  dualprobe::SvfConfig<S> c;
  c.sample_interval = S(0.01);
  c.filter_time_constant = S(0.6);
  EXPECT_EQ(svf.configure(c), dualprobe::Status::ok);
  for (std::size_t k = 0; k < series.t1.size(); ++k) {
    if (k >= 15000 && k < 15300) continue;
    if (k == 15300 && use_break) svf.break_chain(std::uint64_t(25 * 60));
    svf.update(S(series.t1[k]), S(series.t2[k]));
  }
  return svf.solve();
}

// The ZOH difference-equation data are not exactly the FOH model of the SVF: the estimate is
// within ~0.5 % of the truth without any gap; with the gap and break_chain it stays there
// (1 % bound), while joining the gap without the break biases it by several percent.
TYPED_TEST(EcuExtensions, BreakChainSkipsTheGapTransient) {
  using S = TypeParam;
  const auto with_break = run_with_gap<S>(true);
  ASSERT_EQ(with_break.status, dualprobe::Status::ok);
  const double e1 = std::fabs(double(with_break.time_constants1[0]) / 1.248 - 1.0);
  const double e2 = std::fabs(double(with_break.time_constants2[0]) / 2.895 - 1.0);
  EXPECT_LT(e1, 0.01);
  EXPECT_LT(e2, 0.01);
  const auto without = run_with_gap<S>(false);
  const double f1 = without.status == dualprobe::Status::ok
                        ? std::fabs(double(without.time_constants1[0]) / 1.248 - 1.0)
                        : 1.0;
  const double f2 = without.status == dualprobe::Status::ok
                        ? std::fabs(double(without.time_constants2[0]) / 2.895 - 1.0)
                        : 1.0;
  EXPECT_GT(f1 + f2, 2.0 * (e1 + e2));
}

// set_model with the transition and noise that configure() computed reproduces the
// unscheduled filter bit for bit; a non-finite entry is refused and changes nothing.
TYPED_TEST(EcuExtensions, SetModelWithTheConfiguredModelIsIdentity) {
  using S = TypeParam;
  using K = dualprobe::KalmanFirstOrder<S, 16>;
  dualprobe::KalmanConfig<S> c;
  c.sample_interval = S(0.01);
  c.taus1[0] = S(1.2);
  c.taus2[0] = S(3.0);
  c.sigma1 = c.sigma2 = S(0.02);
  c.intensity = S(5);
  c.window = 16;
  K a;
  K b;
  ASSERT_EQ(a.configure(c), dualprobe::Status::ok);
  ASSERT_EQ(b.configure(c), dualprobe::Status::ok);
  const auto phi = b.transition(0);
  const auto q = b.process_noise(0);
  auto broken = phi;
  broken(1, 1) = std::numeric_limits<S>::quiet_NaN();
  const auto series = dualprobe::test::difference_equation_pair(3000, 1.2, 3.0, 0.01, 9u, 200);
  for (std::size_t k = 0; k < series.t1.size(); ++k) {
    EXPECT_EQ(b.set_model(broken, q), dualprobe::Status::invalid_argument);
    ASSERT_EQ(b.set_model(phi, q), dualprobe::Status::ok);
    S ga = 0;
    S gb = 0;
    ASSERT_EQ(a.update(S(series.t1[k]), S(series.t2[k]), &ga), dualprobe::Status::ok);
    ASSERT_EQ(b.update(S(series.t1[k]), S(series.t2[k]), &gb), dualprobe::Status::ok);
    ASSERT_EQ(ga, gb);
  }
  EXPECT_EQ(a.jump_count(), b.jump_count());
  K unconfigured;
  EXPECT_EQ(unconfigured.set_model(phi, q), dualprobe::Status::invalid_argument);
}

}  // namespace
