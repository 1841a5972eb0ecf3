#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "dualprobe/difference_estimator.hpp"
#include "test_support.hpp"

namespace {

using dualprobe::Method;

std::string method_name(const ::testing::TestParamInfo<Method>& info) {
  switch (info.param) {
    case Method::ls: return "ls";
    case Method::tls: return "tls";
    case Method::gtls: return "gtls";
  }
  return "unknown";
}
using dualprobe::Status;

constexpr double kTau1 = 12.48;  // the paper's 1.5 mm Pt-100
constexpr double kTau2 = 28.95;  // the paper's 4.5 mm Pt-100
constexpr double kTs = 1.0;

template <typename S>
dualprobe::DifferenceEstimator<S> make_estimator(Method method, S forgetting = S(1)) {
  dualprobe::DifferenceEstimator<S> estimator;
  dualprobe::DifferenceConfig<S> config;
  config.sample_interval = S(kTs);
  config.method = method;
  config.sigma1 = S(0.05);
  config.sigma2 = S(0.05);
  config.forgetting = forgetting;
  EXPECT_EQ(estimator.configure(config), Status::ok);
  return estimator;
}

template <typename S>
void feed(dualprobe::DifferenceEstimator<S>& estimator, const dualprobe::test::PairSeries& series) {
  for (std::size_t k = 0; k < series.t1.size(); ++k) {
    ASSERT_EQ(estimator.update(S(series.t1[k]), S(series.t2[k])), Status::ok);
  }
}

class ExactnessDouble : public ::testing::TestWithParam<Method> {};

TEST_P(ExactnessDouble, NoiseFreeDifferenceEquationIsRecoveredExactly) {
  const auto series = dualprobe::test::difference_equation_pair(2000, kTau1, kTau2, kTs);
  auto estimator = make_estimator<double>(GetParam());
  feed(estimator, series);
  const auto result = estimator.solve();
  ASSERT_EQ(result.status, Status::ok);
  const double b1 = -std::expm1(-kTs / kTau1);
  const double b2 = -std::expm1(-kTs / kTau2);
  // Issue 2: theta to 1e-10 relative, time constants to 1e-8 s in double.
  EXPECT_NEAR(result.beta, b2 / b1, 1e-10 * (b2 / b1));
  EXPECT_NEAR(result.b2, b2, 1e-10 * b2);
  EXPECT_NEAR(result.tau1, kTau1, 1e-8);
  EXPECT_NEAR(result.tau2, kTau2, 1e-8);
}

INSTANTIATE_TEST_SUITE_P(AllMethods, ExactnessDouble,
                         ::testing::Values(Method::ls, Method::tls, Method::gtls), method_name);

class ExactnessFloat : public ::testing::TestWithParam<Method> {};

TEST_P(ExactnessFloat, NoiseFreeWithinFloatTolerance) {
  const auto series = dualprobe::test::difference_equation_pair(2000, kTau1, kTau2, kTs);
  auto estimator = make_estimator<float>(GetParam());
  feed(estimator, series);
  const auto result = estimator.solve();
  ASSERT_EQ(result.status, Status::ok);
  // Issue 2: float within 1e-4 relative (samples of ~300 K carry ~2e-5 K rounding against
  // differences of ~1 K, so 1e-4 is a few float ulps of the regression, not slack).
  EXPECT_NEAR(result.tau1, kTau1, 1e-4 * kTau1);
  EXPECT_NEAR(result.tau2, kTau2, 1e-4 * kTau2);
}

INSTANTIATE_TEST_SUITE_P(AllMethods, ExactnessFloat,
                         ::testing::Values(Method::ls, Method::tls, Method::gtls), method_name);

TEST(DifferenceEstimator, NonFiniteSampleIsRefusedAndBreaksTheChain) {
  const auto series = dualprobe::test::difference_equation_pair(500, kTau1, kTau2, kTs);
  auto estimator = make_estimator<double>(Method::gtls);
  auto reference = make_estimator<double>(Method::gtls);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  for (std::size_t k = 0; k < series.t1.size(); ++k) {
    if (k == 100) {
      const auto before = estimator.scatter();
      EXPECT_EQ(estimator.update(nan, 1.0), Status::non_finite_input);
      EXPECT_EQ(estimator.update(1.0, inf), Status::non_finite_input);
      EXPECT_EQ(estimator.update(-inf, nan), Status::non_finite_input);
      EXPECT_EQ(estimator.scatter(), before);  // the accumulated data are kept
      reference.break_chain();  // ... and the chain is broken, as by break_chain()
    }
    estimator.update(series.t1[k], series.t2[k]);
    reference.update(series.t1[k], series.t2[k]);
  }
  EXPECT_EQ(estimator.scatter(), reference.scatter());
  EXPECT_EQ(estimator.rows(), reference.rows());
}

// Issue 12: a NaN that *replaces* a sample. update() and update_block() both drop the two
// differences that touch it; no row spans 2 Ts (before the fix update() formed one from the
// samples either side of the NaN).
TEST(DifferenceEstimator, NanReplacingASampleDropsItsTwoDifferences) {
  const auto series = dualprobe::test::difference_equation_pair(600, kTau1, kTau2, kTs);
  const std::size_t n = series.t1.size();
  for (const std::size_t replaced : {std::size_t{1}, std::size_t{250}, n - 2}) {
    std::vector<double> t1 = series.t1, t2 = series.t2;
    t1[replaced] = std::numeric_limits<double>::quiet_NaN();
    // The scatter of the record without rows k = replaced and k = replaced + 1, summed here.
    Eigen::Matrix3d expected = Eigen::Matrix3d::Zero();
    double expected_rows = 0.0;
    for (std::size_t k = 1; k < n; ++k) {
      if (k == replaced || k == replaced + 1) continue;
      const Eigen::Vector3d z(t1[k] - t1[k - 1], t1[k - 1] - t2[k - 1], t2[k] - t2[k - 1]);
      expected += z * z.transpose();
      expected_rows += 1.0;
    }
    auto single = make_estimator<double>(Method::gtls);
    for (std::size_t k = 0; k < n; ++k) {
      EXPECT_EQ(single.update(t1[k], t2[k]) == Status::ok, k != replaced) << k;
    }
    auto block = make_estimator<double>(Method::gtls);
    EXPECT_EQ(block.update_block(t1.data(), t2.data(), n), 1u);
    EXPECT_EQ(single.rows(), expected_rows) << replaced;  // n - 3: one chain lost 2 rows
    EXPECT_EQ(expected_rows, double(n - 3));
    const double scale = expected.cwiseAbs().maxCoeff();
    EXPECT_LE((single.scatter() - expected).cwiseAbs().maxCoeff(), 1e-12 * scale) << replaced;
    // update() and update_block() agree to the last bit.
    EXPECT_EQ(block.scatter(), single.scatter());
    EXPECT_EQ(block.rows(), single.rows());
    const auto a = single.solve(), b = block.solve();
    ASSERT_EQ(a.status, Status::ok);
    EXPECT_EQ(a.tau1, b.tau1);
    EXPECT_EQ(a.tau2, b.tau2);
    // Dropping two rows of exact difference-equation data leaves the estimate exact.
    EXPECT_NEAR(a.tau1, kTau1, 1e-8);
    EXPECT_NEAR(a.tau2, kTau2, 1e-8);
  }
}

TEST(DifferenceEstimator, InvalidConfigurationLeavesEstimatorUntouched) {
  auto estimator = make_estimator<double>(Method::gtls);
  const auto series = dualprobe::test::difference_equation_pair(100, kTau1, kTau2, kTs);
  feed(estimator, series);
  const auto before = estimator.scatter();
  dualprobe::DifferenceConfig<double> bad;
  bad.sample_interval = -1.0;
  EXPECT_EQ(estimator.configure(bad), Status::invalid_argument);
  bad.sample_interval = 1.0;
  bad.forgetting = 1.5;
  EXPECT_EQ(estimator.configure(bad), Status::invalid_argument);
  bad.forgetting = 1.0;
  bad.method = Method::gtls;
  bad.sigma1 = 0.0;  // GTLS needs a noise model
  EXPECT_EQ(estimator.configure(bad), Status::invalid_argument);
  EXPECT_EQ(estimator.scatter(), before);
  EXPECT_DOUBLE_EQ(estimator.config().sample_interval, kTs);
}

TEST(DifferenceEstimator, ConstantSignalsAreInsufficientExcitation) {
  for (Method method : {Method::ls, Method::tls, Method::gtls}) {
    auto estimator = make_estimator<double>(method);
    for (int k = 0; k < 200; ++k) estimator.update(300.0, 300.0);
    EXPECT_EQ(estimator.solve().status, Status::insufficient_excitation);
  }
}

TEST(DifferenceEstimator, TooFewSamplesIsInsufficientExcitation) {
  auto estimator = make_estimator<double>(Method::ls);
  EXPECT_EQ(estimator.solve().status, Status::insufficient_excitation);
  estimator.update(1.0, 2.0);
  estimator.update(2.0, 2.5);
  EXPECT_EQ(estimator.solve().status, Status::insufficient_excitation);
}

TEST(DifferenceEstimator, SwappedSensorsGiveInfeasibleOrSwappedEstimate) {
  // Sensor 2 "faster" than physics allows: data from a sensor pair where T2 leads and the
  // relation has a negative b. Built as an anti-physical series: T2 = T1 shifted ahead.
  auto estimator = make_estimator<double>(Method::ls);
  for (int k = 0; k < 400; ++k) {
    const double t1 = std::sin(0.05 * k);
    const double t2 = -std::sin(0.05 * k);  // anti-correlated: no first-order pair does this
    estimator.update(t1, t2);
  }
  EXPECT_EQ(estimator.solve().status, Status::infeasible);
}

TEST(DifferenceEstimator, ForgettingTracksStepChangeOfTimeConstants) {
  // First half: taus 12.48/28.95; second half: the gas velocity drops, both grow by 40%.
  const auto first = dualprobe::test::difference_equation_pair(3000, kTau1, kTau2, kTs, 3u);
  const auto second =
      dualprobe::test::difference_equation_pair(3000, 1.4 * kTau1, 1.4 * kTau2, kTs, 5u);
  auto forgetting = make_estimator<double>(Method::ls, 0.995);  // memory ~200 samples
  auto plain = make_estimator<double>(Method::ls);
  feed(forgetting, first);
  feed(plain, first);
  forgetting.break_chain();  // the second series starts from its own initial state
  plain.break_chain();
  feed(forgetting, second);
  feed(plain, second);
  const auto tracked = forgetting.solve();
  const auto stale = plain.solve();
  ASSERT_EQ(tracked.status, Status::ok);
  // Noise-free data: after ~14 memory lengths the first half's weight is ~e^-15.
  EXPECT_NEAR(tracked.tau1, 1.4 * kTau1, 1e-6 * kTau1);
  EXPECT_NEAR(tracked.tau2, 1.4 * kTau2, 1e-6 * kTau2);
  // Without forgetting the estimate mixes both regimes and misses the new value by > 5%.
  EXPECT_TRUE(stale.status != Status::ok || std::abs(stale.tau1 / (1.4 * kTau1) - 1.0) > 0.05 ||
              std::abs(stale.tau2 / (1.4 * kTau2) - 1.0) > 0.05);
}

TEST(DifferenceEstimator, GtlsNoiseCovarianceMatchesDerivation) {
  const auto c = dualprobe::difference_noise_covariance(0.1, 0.2);
  EXPECT_DOUBLE_EQ(c(0, 0), 2 * 0.01);
  EXPECT_DOUBLE_EQ(c(0, 1), -0.01);
  EXPECT_DOUBLE_EQ(c(1, 1), 0.01 + 0.04);
  EXPECT_DOUBLE_EQ(c(1, 2), 0.04);
  EXPECT_DOUBLE_EQ(c(2, 2), 0.08);
  EXPECT_DOUBLE_EQ(c(0, 2), 0.0);
  EXPECT_EQ(c, c.transpose());
}

}  // namespace

namespace {

template <typename T>
class BlockUpdateTest : public ::testing::Test {};
using BlockScalars = ::testing::Types<float, double>;
TYPED_TEST_SUITE(BlockUpdateTest, BlockScalars);

TYPED_TEST(BlockUpdateTest, BlockEqualsSampleBySampleIncludingGaps) {
  using S = TypeParam;
  const auto series = dualprobe::test::difference_equation_pair(7000, kTau1, kTau2, kTs);
  std::vector<S> t1(series.t1.begin(), series.t1.end());
  std::vector<S> t2(series.t2.begin(), series.t2.end());
  t1[100] = std::numeric_limits<S>::quiet_NaN();
  t2[5000] = std::numeric_limits<S>::infinity();
  for (S forgetting : {S(1), S(0.999)}) {
    auto block = make_estimator<S>(Method::gtls, forgetting);
    auto single = make_estimator<S>(Method::gtls, forgetting);
    // Uneven chunks so runs cross the internal block size and the chunk borders.
    const std::size_t cuts[] = {0, 3, 2500, 2501, 4999, 7000};
    std::size_t refused = 0;
    for (std::size_t c = 0; c + 1 < sizeof(cuts) / sizeof(cuts[0]); ++c) {
      refused += block.update_block(t1.data() + cuts[c], t2.data() + cuts[c], cuts[c + 1] - cuts[c]);
    }
    for (std::size_t k = 0; k < t1.size(); ++k) {
      if (single.update(t1[k], t2[k]) != Status::ok) single.break_chain();
    }
    EXPECT_EQ(refused, 2u);
    // Same operations in the same order: equal to the last bit.
    EXPECT_EQ(block.scatter(), single.scatter());
    EXPECT_EQ(block.solve().tau1, single.solve().tau1);
  }
}

}  // namespace
