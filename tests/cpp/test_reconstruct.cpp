#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "dualprobe/reconstruct.hpp"
#include "test_support.hpp"

namespace {

using dualprobe::Status;

TEST(Reconstruct, ExactInverseRecoversGasTemperature) {
  const auto series = dualprobe::test::difference_equation_pair(1500, 12.48, 28.95, 0.1);
  std::vector<double> out(series.t1.size());
  ASSERT_EQ(dualprobe::reconstruct_inverse(series.t1.data(), series.t1.size(), 12.48, 0.1,
                                           out.data()),
            Status::ok);
  for (std::size_t k = 0; k + 1 < out.size(); ++k) {
    // Issue 2: reconstruction to 1e-9 K in double.
    ASSERT_NEAR(out[k], series.gas[k], 1e-9) << "sample " << k;
  }
  EXPECT_TRUE(std::isnan(out.back()));
}

TEST(Reconstruct, StreamingWeightedMatchesGasForEveryChoiceOfSource) {
  const auto series = dualprobe::test::difference_equation_pair(800, 12.48, 28.95, 0.1);
  for (auto source : {dualprobe::ReconstructionSource::sensor1,
                      dualprobe::ReconstructionSource::sensor2,
                      dualprobe::ReconstructionSource::weighted}) {
    dualprobe::InverseReconstructor<double> rec;
    dualprobe::InverseReconstructor<double>::Config config;
    config.sample_interval = 0.1;
    config.tau1 = 12.48;
    config.tau2 = 28.95;
    config.source = source;
    ASSERT_EQ(rec.configure(config), Status::ok);
    double gas = 0.0;
    EXPECT_EQ(rec.update(series.t1[0], series.t2[0], &gas), Status::not_ready);
    for (std::size_t k = 1; k < series.t1.size(); ++k) {
      ASSERT_EQ(rec.update(series.t1[k], series.t2[k], &gas), Status::ok);
      ASSERT_NEAR(gas, series.gas[k - 1], 1e-9);
    }
  }
}

TEST(Reconstruct, LowPassBoundsNoiseGainAndKeepsLevel) {
  dualprobe::InverseReconstructor<double> rec;
  dualprobe::InverseReconstructor<double>::Config config;
  config.sample_interval = 0.1;
  config.tau1 = 10.0;
  config.tau2 = 20.0;
  config.lowpass_tau = 1.0;
  ASSERT_EQ(rec.configure(config), Status::ok);
  double gas = 0.0;
  // Alternating +/-0.1 K "noise" on a steady 100 degC: the bare inverse amplifies it by
  // ~2 tau/Ts = 200; the 1 s low-pass must cut the ripple by more than 10x.
  double max_dev = 0.0;
  for (int k = 0; k < 400; ++k) {
    const double e = (k % 2 == 0) ? 0.1 : -0.1;
    if (rec.update(100.0 + e, 100.0 + e, &gas) == Status::ok && k > 200) {
      max_dev = std::max(max_dev, std::abs(gas - 100.0));
    }
  }
  EXPECT_LT(max_dev, 0.1 * 200 * 0.1);
}

TEST(Reconstruct, RejectsBadConfigurationAndNonFiniteSamples) {
  dualprobe::InverseReconstructor<float> rec;
  dualprobe::InverseReconstructor<float>::Config config;
  config.tau1 = -1.0f;
  EXPECT_EQ(rec.configure(config), Status::invalid_argument);
  config.tau1 = 1.0f;
  ASSERT_EQ(rec.configure(config), Status::ok);
  float gas = 5.0f;
  EXPECT_EQ(rec.update(std::nanf(""), 1.0f, &gas), Status::non_finite_input);
  EXPECT_EQ(gas, 5.0f);
}

}  // namespace
