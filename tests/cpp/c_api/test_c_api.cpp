// The C API (dualprobe.h) against the C++ core it wraps, its documented contract (statuses,
// refused samples, bad arguments) and the physics on noise-free data.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "dualprobe/difference_estimator.hpp"
#include "dualprobe/dualprobe.h"
#include "dualprobe/reconstruct.hpp"
#include "signals.hpp"

namespace {

constexpr float kNan = std::numeric_limits<float>::quiet_NaN();
constexpr float kInf = std::numeric_limits<float>::infinity();

dp_diff_config_f32 config(dp_method method, float forgetting = 1.0f) {
  return dp_diff_config_f32{0.01f, method, 0.02f, 0.02f, forgetting};
}

struct Series {
  std::vector<float> t1, t2;
  std::vector<double> gas;
};

Series realistic(std::size_t n, std::uint64_t seed = 3, double noise = 0.02) {
  dualprobe_test::PairSource source(seed);
  source.noise1 = noise;
  source.noise2 = noise;
  source.start();
  Series s;
  for (std::size_t k = 0; k < n; ++k) {
    double a = 0, b = 0;
    source.next(&a, &b);
    s.t1.push_back(static_cast<float>(a));
    s.t2.push_back(static_cast<float>(b));
    s.gas.push_back(source.gas());
  }
  return s;
}

std::vector<float> scatter(const dp_diff_instance_f32& instance) {
  std::vector<float> packed(6);
  EXPECT_EQ(dp_diff_scatter_f32(&instance, packed.data()), DP_STATUS_OK);
  return packed;
}

bool same_bits(float a, float b) { return std::memcmp(&a, &b, sizeof a) == 0; }

// Out-of-range enum values as a C caller can store them (a C++ cast would be undefined).
dp_diff_config_f32 with_method(int method) {
  dp_diff_config_f32 c = {0.01f, DP_METHOD_LS, 0.0f, 0.0f, 1.0f};
  std::memcpy(&c.method, &method, sizeof method);
  return c;
}

TEST(CApiLayout, InstanceSizesAreFixedAndWithinTheEcuBudget) {
  static_assert(sizeof(dp_diff_instance_f32) == DP_DIFF_INSTANCE_BYTES, "layout");
  static_assert(sizeof(dp_recon_instance_f32) == DP_RECON_INSTANCE_BYTES, "layout");
  EXPECT_LE(sizeof(dp_diff_instance_f32), 128u);  // issue 4: estimator state <= 128 bytes
  EXPECT_GE(sizeof(dp_diff_instance_f32), sizeof(dualprobe::DifferenceEstimator<float>));
}

class CApiMethod : public ::testing::TestWithParam<dp_method> {};

// The C API is a thin layer: the same float arithmetic as the core, bit for bit.
TEST_P(CApiMethod, UpdateAndSolveEqualTheCoreBitForBit) {
  for (const float forgetting : {1.0f, 0.9995f}) {
    const Series s = realistic(5000);
    dp_diff_instance_f32 instance;
    const dp_diff_config_f32 c = config(GetParam(), forgetting);
    ASSERT_EQ(dp_diff_init_f32(&instance, &c), DP_STATUS_OK);
    dualprobe::DifferenceEstimator<float> core;
    dualprobe::DifferenceConfig<float> cc;
    cc.sample_interval = c.sample_interval;
    cc.method = static_cast<dualprobe::Method>(c.method);
    cc.sigma1 = c.sigma1;
    cc.sigma2 = c.sigma2;
    cc.forgetting = c.forgetting;
    ASSERT_EQ(core.configure(cc), dualprobe::Status::ok);
    for (std::size_t k = 0; k < s.t1.size(); ++k) {
      ASSERT_EQ(dp_diff_update_f32(&instance, s.t1[k], s.t2[k]), DP_STATUS_OK);
      core.update(s.t1[k], s.t2[k]);
    }
    dp_diff_result_f32 r;
    const auto expected = core.solve();
    ASSERT_EQ(dp_diff_solve_f32(&instance, &r), static_cast<dp_status>(expected.status));
    ASSERT_EQ(r.status, DP_STATUS_OK);
    EXPECT_TRUE(same_bits(r.beta, expected.beta));
    EXPECT_TRUE(same_bits(r.b1, expected.b1));
    EXPECT_TRUE(same_bits(r.b2, expected.b2));
    EXPECT_TRUE(same_bits(r.tau1, expected.tau1));
    EXPECT_TRUE(same_bits(r.tau2, expected.tau2));
    EXPECT_EQ(dp_diff_rows_f32(&instance), core.rows());
  }
}

INSTANTIATE_TEST_SUITE_P(Methods, CApiMethod,
                         ::testing::Values(DP_METHOD_LS, DP_METHOD_TLS, DP_METHOD_GTLS));

TEST(CApi, NoiseFreePairGivesTheTrueTimeConstants) {
  const Series s = realistic(20000, 5, 0.0);
  dp_diff_instance_f32 instance;
  const dp_diff_config_f32 c = {0.01f, DP_METHOD_TLS, 0.0f, 0.0f, 1.0f};
  ASSERT_EQ(dp_diff_init_f32(&instance, &c), DP_STATUS_OK);
  ASSERT_EQ(dp_diff_update_block_f32(&instance, s.t1.data(), s.t2.data(),
                                     static_cast<uint32_t>(s.t1.size())),
            DP_STATUS_OK);
  dp_diff_result_f32 r;
  ASSERT_EQ(dp_diff_solve_f32(&instance, &r), DP_STATUS_OK);
  // Float rounding of the samples (ulp 1.5e-5 K at 200 C) is the only noise: against per-sample
  // differences of ~0.05 K it leaves a TLS bias well under 0.5 %.
  EXPECT_NEAR(r.tau1, 1.248, 0.005 * 1.248);
  EXPECT_NEAR(r.tau2, 2.895, 0.005 * 2.895);
  EXPECT_GT(r.beta, 0.0f);
  EXPECT_NEAR(r.b1, r.b2 / r.beta, 1e-6f * r.b1);  // b1 = b2 / beta by definition
}

TEST(CApi, NonFiniteSamplesAreRefusedKeepTheDataAndBreakTheChain) {
  const Series s = realistic(600);
  dp_diff_instance_f32 fed, twin;
  const dp_diff_config_f32 c = config(DP_METHOD_GTLS, 0.999f);
  ASSERT_EQ(dp_diff_init_f32(&fed, &c), DP_STATUS_OK);
  ASSERT_EQ(dp_diff_init_f32(&twin, &c), DP_STATUS_OK);
  for (std::size_t k = 0; k < s.t1.size(); ++k) {
    ASSERT_EQ(dp_diff_update_f32(&twin, s.t1[k], s.t2[k]), DP_STATUS_OK);
    ASSERT_EQ(dp_diff_update_f32(&fed, s.t1[k], s.t2[k]), DP_STATUS_OK);
    if (k % 50 == 25) {
      const auto before = scatter(fed);
      const float rows = dp_diff_rows_f32(&fed);
      for (const auto& bad : {std::pair{kNan, 1.0f}, std::pair{1.0f, kNan},
                              std::pair{kInf, 1.0f}, std::pair{1.0f, -kInf},
                              std::pair{kNan, kInf}}) {
        EXPECT_EQ(dp_diff_update_f32(&fed, bad.first, bad.second), DP_STATUS_NON_FINITE_INPUT);
      }
      EXPECT_EQ(scatter(fed), before);  // the accumulated data are untouched
      EXPECT_EQ(dp_diff_rows_f32(&fed), rows);
      dp_diff_break_chain_f32(&twin);  // ... and the chain is broken
    }
  }
  // Refused samples break the chain: the next sample starts new differences, no row spans
  // the refused one.
  EXPECT_EQ(scatter(fed), scatter(twin));
  EXPECT_EQ(dp_diff_rows_f32(&fed), dp_diff_rows_f32(&twin));
}

TEST(CApi, BadArgumentsAreReportedNotFollowed) {
  dp_diff_instance_f32 instance;
  const dp_diff_config_f32 good = config(DP_METHOD_GTLS);
  const std::vector<dp_diff_config_f32> bad = {
      {0.0f, DP_METHOD_GTLS, 0.02f, 0.02f, 1.0f},   {-1.0f, DP_METHOD_GTLS, 0.02f, 0.02f, 1.0f},
      {kNan, DP_METHOD_GTLS, 0.02f, 0.02f, 1.0f},   {kInf, DP_METHOD_GTLS, 0.02f, 0.02f, 1.0f},
      {0.01f, DP_METHOD_GTLS, 0.0f, 0.02f, 1.0f},   {0.01f, DP_METHOD_GTLS, 0.02f, kNan, 1.0f},
      {0.01f, DP_METHOD_GTLS, 0.02f, 0.02f, 0.0f},  {0.01f, DP_METHOD_GTLS, 0.02f, 0.02f, 1.5f},
      {0.01f, DP_METHOD_GTLS, 0.02f, 0.02f, kNan},  with_method(7), with_method(-1),
  };
  const Series s = realistic(500);
  for (const auto& c : bad) {
    EXPECT_EQ(dp_diff_init_f32(&instance, &c), DP_STATUS_INVALID_ARGUMENT);
    // Still a defined state: updates are harmless, solve keeps saying the config is bad.
    for (std::size_t k = 0; k < s.t1.size(); ++k) dp_diff_update_f32(&instance, s.t1[k], s.t2[k]);
    dp_diff_result_f32 r;
    EXPECT_EQ(dp_diff_solve_f32(&instance, &r), DP_STATUS_INVALID_ARGUMENT);
    EXPECT_EQ(r.status, DP_STATUS_INVALID_ARGUMENT);
  }
  EXPECT_EQ(dp_diff_init_f32(nullptr, &good), DP_STATUS_INVALID_ARGUMENT);
  EXPECT_EQ(dp_diff_init_f32(&instance, nullptr), DP_STATUS_INVALID_ARGUMENT);
  EXPECT_EQ(dp_diff_update_f32(nullptr, 1.0f, 2.0f), DP_STATUS_INVALID_ARGUMENT);
  dp_diff_result_f32 r;
  EXPECT_EQ(dp_diff_solve_f32(nullptr, &r), DP_STATUS_INVALID_ARGUMENT);
  ASSERT_EQ(dp_diff_init_f32(&instance, &good), DP_STATUS_OK);
  EXPECT_EQ(dp_diff_solve_f32(&instance, nullptr), DP_STATUS_INVALID_ARGUMENT);
  EXPECT_EQ(dp_diff_update_block_f32(&instance, nullptr, nullptr, 3), DP_STATUS_INVALID_ARGUMENT);
  EXPECT_EQ(dp_diff_update_block_f32(&instance, nullptr, nullptr, 0), DP_STATUS_OK);
  EXPECT_EQ(dp_diff_scatter_f32(&instance, nullptr), DP_STATUS_INVALID_ARGUMENT);
  EXPECT_EQ(dp_diff_rows_f32(nullptr), 0.0f);
  dp_diff_reset_f32(nullptr);
  dp_diff_break_chain_f32(nullptr);
}

TEST(CApi, TooFewOrUnexcitedSamplesAreInsufficientExcitation) {
  dp_diff_instance_f32 instance;
  const dp_diff_config_f32 c = config(DP_METHOD_GTLS);
  ASSERT_EQ(dp_diff_init_f32(&instance, &c), DP_STATUS_OK);
  dp_diff_result_f32 r;
  for (int k = 0; k < 3; ++k) {  // 0, 1, 2 samples: at most one row
    EXPECT_EQ(dp_diff_solve_f32(&instance, &r), DP_STATUS_INSUFFICIENT_EXCITATION);
    dp_diff_update_f32(&instance, 200.0f + static_cast<float>(k), 199.0f);
  }
  dp_diff_reset_f32(&instance);
  for (int k = 0; k < 1000; ++k) dp_diff_update_f32(&instance, 250.0f, 250.0f);  // flat
  EXPECT_EQ(dp_diff_solve_f32(&instance, &r), DP_STATUS_INSUFFICIENT_EXCITATION);
  EXPECT_EQ(dp_diff_rows_f32(&instance), 999.0f);
  dp_diff_reset_f32(&instance);
  EXPECT_EQ(dp_diff_rows_f32(&instance), 0.0f);
}

TEST(CApi, BlockUpdateEqualsSampleBySample) {
  Series s = realistic(1000);
  s.t1[400] = kNan;  // refused inside the block; the first non-ok status is returned
  dp_diff_instance_f32 block, single;
  const dp_diff_config_f32 c = config(DP_METHOD_GTLS, 0.999f);
  ASSERT_EQ(dp_diff_init_f32(&block, &c), DP_STATUS_OK);
  ASSERT_EQ(dp_diff_init_f32(&single, &c), DP_STATUS_OK);
  EXPECT_EQ(dp_diff_update_block_f32(&block, s.t1.data(), s.t2.data(), 1000u),
            DP_STATUS_NON_FINITE_INPUT);
  for (std::size_t k = 0; k < 1000; ++k) dp_diff_update_f32(&single, s.t1[k], s.t2[k]);
  EXPECT_EQ(scatter(block), scatter(single));
}

// Issue 12: a NaN that *replaces* a sample breaks the chain in dp_diff_update_f32 and in
// dp_diff_update_block_f32 alike: the two differences touching it are dropped, no row spans
// 2 Ts, and the result equals a break at that sample.
TEST(CApi, NanReplacingASampleBreaksTheChain) {
  const std::size_t n = 1000, replaced = 400;
  Series s = realistic(n);
  s.t2[replaced] = kNan;
  dp_diff_instance_f32 single, block, broken;
  const dp_diff_config_f32 c = config(DP_METHOD_GTLS);
  ASSERT_EQ(dp_diff_init_f32(&single, &c), DP_STATUS_OK);
  ASSERT_EQ(dp_diff_init_f32(&block, &c), DP_STATUS_OK);
  ASSERT_EQ(dp_diff_init_f32(&broken, &c), DP_STATUS_OK);
  for (std::size_t k = 0; k < n; ++k) {
    const dp_status status = dp_diff_update_f32(&single, s.t1[k], s.t2[k]);
    EXPECT_EQ(status, k == replaced ? DP_STATUS_NON_FINITE_INPUT : DP_STATUS_OK) << k;
    if (k == replaced) {
      dp_diff_break_chain_f32(&broken);
    } else {
      dp_diff_update_f32(&broken, s.t1[k], s.t2[k]);
    }
  }
  EXPECT_EQ(dp_diff_update_block_f32(&block, s.t1.data(), s.t2.data(), static_cast<uint32_t>(n)),
            DP_STATUS_NON_FINITE_INPUT);
  // Rows 1..n-1 less the two that touch the replaced sample.
  EXPECT_EQ(dp_diff_rows_f32(&single), float(n - 3));
  EXPECT_EQ(dp_diff_rows_f32(&block), float(n - 3));
  EXPECT_EQ(scatter(single), scatter(broken));
  EXPECT_EQ(scatter(block), scatter(broken));
  dp_diff_result_f32 a, b;
  EXPECT_EQ(dp_diff_solve_f32(&single, &a), dp_diff_solve_f32(&broken, &b));
  EXPECT_TRUE(same_bits(a.tau1, b.tau1) && same_bits(a.tau2, b.tau2));
}

TEST(CApi, BreakChainStartsANewChainAndKeepsTheData) {
  const Series s = realistic(2000);
  dp_diff_instance_f32 whole, first, second;
  const dp_diff_config_f32 c = config(DP_METHOD_GTLS);
  ASSERT_EQ(dp_diff_init_f32(&whole, &c), DP_STATUS_OK);
  ASSERT_EQ(dp_diff_init_f32(&first, &c), DP_STATUS_OK);
  ASSERT_EQ(dp_diff_init_f32(&second, &c), DP_STATUS_OK);
  for (std::size_t k = 0; k < 1000; ++k) {
    dp_diff_update_f32(&whole, s.t1[k], s.t2[k]);
    dp_diff_update_f32(&first, s.t1[k], s.t2[k]);
  }
  dp_diff_break_chain_f32(&whole);
  for (std::size_t k = 1300; k < 2000; ++k) {  // 300 samples lost to a fault
    dp_diff_update_f32(&whole, s.t1[k], s.t2[k]);
    dp_diff_update_f32(&second, s.t1[k], s.t2[k]);
  }
  // No row spans the gap: (1000 - 1) + (700 - 1) rows, and the scatter is the sum of both.
  EXPECT_EQ(dp_diff_rows_f32(&whole), 1698.0f);
  const auto w = scatter(whole), a = scatter(first), b = scatter(second);
  for (int i = 0; i < 6; ++i) {
    // Float sums of ~1000 positive-ish terms in a different order: a few eps * sqrt(n).
    EXPECT_NEAR(w[i], a[i] + b[i], 1e-5f * (std::abs(a[i]) + std::abs(b[i])) + 1e-12f) << i;
  }
}

TEST(CApi, StatusNames) {
  EXPECT_STREQ(dp_status_string(DP_STATUS_OK), "ok");
  EXPECT_STREQ(dp_status_string(DP_STATUS_INSUFFICIENT_EXCITATION), "insufficient_excitation");
  EXPECT_STREQ(dp_status_string(DP_STATUS_INFEASIBLE), "infeasible");
  EXPECT_STREQ(dp_status_string(DP_STATUS_NON_FINITE_INPUT), "non_finite_input");
  EXPECT_STREQ(dp_status_string(DP_STATUS_INVALID_ARGUMENT), "invalid_argument");
  EXPECT_STREQ(dp_status_string(DP_STATUS_NOT_READY), "not_ready");
  // Out-of-range values ("unknown") are checked from C (c99_usage.c), where they are legal.
}

// ---- reconstruction ------------------------------------------------------------------

class CApiSource : public ::testing::TestWithParam<dp_source> {};

TEST_P(CApiSource, ReconstructionEqualsTheCoreBitForBit) {
  for (const float lowpass : {0.0f, 0.05f}) {
    const Series s = realistic(3000);
    const dp_recon_config_f32 c = {0.01f, 1.248f, 2.895f, GetParam(), lowpass};
    dp_recon_instance_f32 instance;
    ASSERT_EQ(dp_recon_init_f32(&instance, &c), DP_STATUS_OK);
    dualprobe::InverseReconstructor<float> core;
    dualprobe::InverseReconstructor<float>::Config cc;
    cc.sample_interval = c.sample_interval;
    cc.tau1 = c.tau1;
    cc.tau2 = c.tau2;
    cc.source = static_cast<dualprobe::ReconstructionSource>(c.source);
    cc.lowpass_tau = c.lowpass_tau;
    ASSERT_EQ(core.configure(cc), dualprobe::Status::ok);
    for (std::size_t k = 0; k < s.t1.size(); ++k) {
      float mine = kNan, theirs = kNan;
      const dp_status status = dp_recon_update_f32(&instance, s.t1[k], s.t2[k], &mine);
      ASSERT_EQ(status, static_cast<dp_status>(core.update(s.t1[k], s.t2[k], &theirs)));
      ASSERT_EQ(status, k == 0 ? DP_STATUS_NOT_READY : DP_STATUS_OK);
      if (status == DP_STATUS_OK) {
        ASSERT_TRUE(same_bits(mine, theirs)) << k;
      }
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Sources, CApiSource,
                         ::testing::Values(DP_SOURCE_SENSOR1, DP_SOURCE_SENSOR2,
                                           DP_SOURCE_WEIGHTED));

TEST(CApiReconstruction, NoiseFreeInverseRecoversTheGas) {
  const Series s = realistic(4000, 9, 0.0);
  const dp_recon_config_f32 c = {0.01f, 1.248f, 2.895f, DP_SOURCE_WEIGHTED, 0.0f};
  dp_recon_instance_f32 instance;
  ASSERT_EQ(dp_recon_init_f32(&instance, &c), DP_STATUS_OK);
  std::vector<float> gas(s.t1.size());
  ASSERT_EQ(dp_recon_block_f32(&instance, s.t1.data(), s.t2.data(), gas.data(),
                               static_cast<uint32_t>(gas.size())),
            DP_STATUS_OK);
  EXPECT_TRUE(std::isnan(gas[0]));
  double worst = 0.0;
  for (std::size_t k = 1; k < gas.size(); ++k) {
    worst = std::max(worst, std::abs(gas[k] - s.gas[k - 1]));  // output k is Tg over [k-1, k)
  }
  // Float samples carry 0.5 ulp (7.6e-6 K at 200 C); the inverse amplifies by about
  // sqrt(1 + a^2)/b (~ 410 for tau2 at 100 Hz), weighted: ~5e-3 K at the very worst.
  EXPECT_LT(worst, 5e-3);
}

TEST(CApiReconstruction, RetuningKeepsTheSampleHistoryAndTheLowPass) {
  const Series s = realistic(400);
  const dp_recon_config_f32 c = {0.01f, 1.0f, 3.0f, DP_SOURCE_WEIGHTED, 0.1f};
  dp_recon_instance_f32 instance;
  ASSERT_EQ(dp_recon_init_f32(&instance, &c), DP_STATUS_OK);
  float gas = 0.0f, previous_gas = 0.0f;
  for (std::size_t k = 0; k < 200; ++k) dp_recon_update_f32(&instance, s.t1[k], s.t2[k], &previous_gas);
  ASSERT_EQ(dp_recon_set_time_constants_f32(&instance, 1.248f, 2.895f), DP_STATUS_OK);
  ASSERT_EQ(dp_recon_update_f32(&instance, s.t1[200], s.t2[200], &gas), DP_STATUS_OK);
  // One low-pass step from the previous output with the retuned inverse, in the same float
  // operations as the implementation.
  const float ts = 0.01f;
  dualprobe::FirstOrderSensor<float> s1, s2;
  s1.set_time_constant(1.248f, ts);
  s2.set_time_constant(2.895f, ts);
  const float w = dualprobe::sensor1_weight(1.248f, 2.895f);
  const float raw = w * s1.inverse(s.t1[200], s.t1[199]) + (1.0f - w) * s2.inverse(s.t2[200], s.t2[199]);
  const float pole = std::exp(-ts / 0.1f);
  EXPECT_TRUE(same_bits(gas, pole * previous_gas + (1.0f - pole) * raw));
  EXPECT_EQ(dp_recon_set_time_constants_f32(&instance, -1.0f, 2.0f), DP_STATUS_INVALID_ARGUMENT);
  EXPECT_EQ(dp_recon_set_time_constants_f32(&instance, 1.0f, kNan), DP_STATUS_INVALID_ARGUMENT);
  // A refused retune leaves the instance as it was.
  float next = 0.0f;
  ASSERT_EQ(dp_recon_update_f32(&instance, s.t1[201], s.t2[201], &next), DP_STATUS_OK);
  const float raw2 = w * s1.inverse(s.t1[201], s.t1[200]) + (1.0f - w) * s2.inverse(s.t2[201], s.t2[200]);
  EXPECT_TRUE(same_bits(next, pole * gas + (1.0f - pole) * raw2));
}

TEST(CApiReconstruction, BadArgumentsAndNonFiniteSamples) {
  dp_recon_instance_f32 instance;
  std::vector<dp_recon_config_f32> bad = {
      {0.0f, 1.0f, 2.0f, DP_SOURCE_WEIGHTED, 0.0f},
      {0.01f, 0.0f, 2.0f, DP_SOURCE_WEIGHTED, 0.0f},
      {0.01f, 1.0f, kInf, DP_SOURCE_WEIGHTED, 0.0f},
      {0.01f, 1.0f, 2.0f, DP_SOURCE_WEIGHTED, -1.0f},
      {0.01f, 1.0f, 2.0f, DP_SOURCE_WEIGHTED, kNan},
      {0.01f, 1.0f, 2.0f, DP_SOURCE_WEIGHTED, 0.0f},  // made invalid below: source 3
  };
  float gas = 123.0f;
  const int invalid_source = 3;
  std::memcpy(&bad.back().source, &invalid_source, sizeof invalid_source);
  for (const auto& c : bad) {
    EXPECT_EQ(dp_recon_init_f32(&instance, &c), DP_STATUS_INVALID_ARGUMENT);
    EXPECT_EQ(dp_recon_update_f32(&instance, 1.0f, 2.0f, &gas), DP_STATUS_INVALID_ARGUMENT);
    EXPECT_EQ(dp_recon_set_time_constants_f32(&instance, 1.0f, 2.0f), DP_STATUS_INVALID_ARGUMENT);
  }
  EXPECT_EQ(gas, 123.0f);
  const dp_recon_config_f32 good = {0.01f, 1.0f, 2.0f, DP_SOURCE_WEIGHTED, 0.0f};
  ASSERT_EQ(dp_recon_init_f32(&instance, &good), DP_STATUS_OK);
  EXPECT_EQ(dp_recon_update_f32(&instance, 200.0f, 200.0f, &gas), DP_STATUS_NOT_READY);
  EXPECT_EQ(dp_recon_update_f32(&instance, kNan, 200.0f, &gas), DP_STATUS_NON_FINITE_INPUT);
  EXPECT_EQ(dp_recon_update_f32(&instance, 200.0f, 200.0f, &gas), DP_STATUS_OK);
  // Steady state: the gas equals both sensors, up to a = 1 - b rounded in float (relative
  // eps / b on the inverse: 200 K * 6e-8 / 0.005 = 2.4e-3 K for tau2 = 2 s at 100 Hz).
  EXPECT_NEAR(gas, 200.0f, 5e-3f);
  dp_recon_reset_f32(&instance);
  EXPECT_EQ(dp_recon_update_f32(&instance, 200.0f, 200.0f, &gas), DP_STATUS_NOT_READY);
  EXPECT_EQ(dp_recon_update_f32(&instance, 200.0f, 200.0f, nullptr), DP_STATUS_INVALID_ARGUMENT);
  EXPECT_EQ(dp_recon_update_f32(nullptr, 200.0f, 200.0f, &gas), DP_STATUS_INVALID_ARGUMENT);
  EXPECT_EQ(dp_recon_init_f32(nullptr, &good), DP_STATUS_INVALID_ARGUMENT);
  EXPECT_EQ(dp_recon_block_f32(&instance, nullptr, nullptr, nullptr, 2), DP_STATUS_INVALID_ARGUMENT);
  dp_recon_reset_f32(nullptr);
}

}  // namespace
