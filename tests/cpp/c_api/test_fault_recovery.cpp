// Recovery after a faulted sensor, at the C API and through the firmware loop
// (firmware_sim/src/firmware.c): faults are flagged on exactly the faulted ticks, the
// estimator pauses and resumes cleanly (no difference spans the gap, the accumulated data
// survive), the reconstruction restarts, and the estimate stays on the truth.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <vector>

#include "dualprobe/dualprobe.h"
#include "signals.hpp"

extern "C" {
#include "adc.h"
#include "firmware.h"
#include "pt100.h"
}

namespace {

constexpr double kTau1 = 1.248;
constexpr double kTau2 = 2.895;

// The ADC front-end of firmware_sim/src/adc.h, in double: IEC 60751 forward equation.
uint32_t counts_of(double temp_c) {
  const double a = 3.9083e-3, b = -5.775e-7, c = -4.183e-12;
  double ratio = 1.0 + a * temp_c + b * temp_c * temp_c;
  if (temp_c < 0.0) ratio += c * (temp_c - 100.0) * temp_c * temp_c * temp_c;
  return static_cast<uint32_t>(std::lround(100.0 * ratio / 400.0 * 16777216.0));
}

struct Fault {
  int channel;  // 1 or 2
  bool open;    // open (railed) or short (near zero)
  uint32_t first, end;
};

struct Recording {
  std::vector<uint32_t> counts1, counts2;
};

Recording record(uint32_t ticks, const std::vector<Fault>& faults, std::uint64_t seed = 11) {
  dualprobe_test::PairSource source(seed);
  source.tau1 = kTau1;
  source.tau2 = kTau2;
  source.start();
  Recording r;
  for (uint32_t k = 0; k < ticks; ++k) {
    double t1 = 0, t2 = 0;
    source.next(&t1, &t2);
    r.counts1.push_back(counts_of(t1));
    r.counts2.push_back(counts_of(t2));
  }
  for (const Fault& f : faults) {
    auto& target = f.channel == 1 ? r.counts1 : r.counts2;
    for (uint32_t k = f.first; k < f.end; ++k) target[k] = f.open ? 0xFFFFFFu : 100u;
  }
  return r;
}

firmware_config calibration(uint32_t ticks) {
  firmware_config c{};
  c.ticks = ticks;
  c.sample_interval = 0.01f;
  c.method = DP_METHOD_GTLS;
  c.sigma1 = 0.02f;
  c.sigma2 = 0.02f;
  c.forgetting = 0.9995f;
  c.solve_every = 100;
  c.resume_after = 10;
  c.source = DP_SOURCE_WEIGHTED;
  c.lowpass_tau = 0.0f;
  return c;
}

TEST(Pt100, CallendarVanDusenInverseMatchesTheForwardEquation) {
  // Float CVD inverse against the double forward equation over the whole IEC range.
  for (double t = -200.0; t <= 850.0; t += 0.37) {
    const double a = 3.9083e-3, b = -5.775e-7, c = -4.183e-12;
    double ratio = 1.0 + a * t + b * t * t;
    if (t < 0.0) ratio += c * (t - 100.0) * t * t * t;
    const float back = pt100_temperature(static_cast<float>(100.0 * ratio));
    // The float resistance alone carries 0.5 ulp (<= 1.5e-5 ohm ~ 4e-5 K); the float
    // arithmetic of the inverse adds a few ulp of T: 2e-4 K covers both.
    EXPECT_NEAR(back, t, 2e-4 + 2e-7 * std::abs(t)) << t;
  }
}

TEST(Adc, OpenAndShortAreClassified) {
  float t = 0.0f;
  EXPECT_EQ(adc_read_channel(0xFFFFFFu, &t), CHANNEL_OPEN);   // railed
  EXPECT_EQ(adc_read_channel(counts_of(900.0), &t), CHANNEL_OPEN);  // beyond 850 C + margin
  EXPECT_EQ(adc_read_channel(100u, &t), CHANNEL_SHORT);
  EXPECT_EQ(adc_read_channel(0u, &t), CHANNEL_SHORT);
  ASSERT_EQ(adc_read_channel(counts_of(300.0), &t), CHANNEL_OK);
  // 24-bit counts: 2.4e-5 ohm per count, ~6e-5 K; rounding to a count is half of that.
  EXPECT_NEAR(t, 300.0, 1e-4);
}

// A twin C API estimator fed the firmware's own temperatures on the ticks it updated, with a
// chain break at every fault: the firmware's solves must equal the twin's bit for bit.
TEST(FirmwareFaults, FlaggedPausedResumedAndEstimateKept) {
  const uint32_t ticks = 12000;
  const std::vector<Fault> faults = {{1, true, 3000, 3300}, {2, false, 7000, 7050},
                                     {1, false, 9000, 9001}};
  const Recording rec = record(ticks, faults);
  const firmware_config config = calibration(ticks);
  static firmware_state state;
  ASSERT_EQ(firmware_init(&state, &config), DP_STATUS_OK);

  dp_diff_instance_f32 twin;
  const dp_diff_config_f32 twin_config = {config.sample_interval, config.method, config.sigma1,
                                          config.sigma2, config.forgetting};
  ASSERT_EQ(dp_diff_init_f32(&twin, &twin_config), DP_STATUS_OK);

  uint32_t last_fault_end = 0;
  bool in_fault = false;
  std::vector<double> tau1_after, tau2_after;
  std::size_t solves_after = 0;
  for (uint32_t k = 0; k < ticks; ++k) {
    tick_output out;
    firmware_tick(&state, rec.counts1[k], rec.counts2[k], &out);
    ASSERT_EQ(out.tick, k);

    uint32_t expected_fault = 0;
    for (const Fault& f : faults) {
      if (k >= f.first && k < f.end) {
        expected_fault |= f.channel == 1 ? (f.open ? FLAG_CH1_OPEN : FLAG_CH1_SHORT)
                                         : (f.open ? FLAG_CH2_OPEN : FLAG_CH2_SHORT);
        last_fault_end = f.end;
      }
    }
    ASSERT_EQ(out.flags & 0x0Fu, expected_fault) << "tick " << k;
    // Paused on the faulted ticks and the first resume_after - 1 healthy ones after.
    const bool expect_paused =
        expected_fault != 0 || (last_fault_end > 0 && k < last_fault_end + config.resume_after - 1);
    ASSERT_EQ((out.flags & FLAG_PAUSED) != 0, expect_paused) << "tick " << k;
    if (expected_fault != 0) {
      ASSERT_TRUE(std::isnan(out.gas));
      if (!in_fault) dp_diff_break_chain_f32(&twin);
      in_fault = true;
    } else {
      in_fault = false;
    }
    if (!expect_paused) {
      ASSERT_TRUE(std::isfinite(out.t1) && std::isfinite(out.t2));
      ASSERT_EQ(dp_diff_update_f32(&twin, out.t1, out.t2), DP_STATUS_OK);
      // The reconstruction restarts one tick after the resume (it needs a previous sample).
      const bool first_after_resume = last_fault_end > 0 && k == last_fault_end + config.resume_after - 1;
      if (k > 2000 && !first_after_resume) {
        ASSERT_TRUE(out.flags & FLAG_GAS_VALID) << k;
      }
      if (first_after_resume) {
        ASSERT_FALSE(out.flags & FLAG_GAS_VALID) << k;
      }
    }
    if (out.flags & FLAG_SOLVED) {
      dp_diff_result_f32 expected;
      dp_diff_solve_f32(&twin, &expected);
      ASSERT_EQ(out.result.status, expected.status) << k;
      ASSERT_EQ(out.result.tau1, expected.tau1) << k;
      ASSERT_EQ(out.result.tau2, expected.tau2) << k;
      if (k > 3000) ++solves_after;
      if (k > 3000 && out.result.status == DP_STATUS_OK) {
        tau1_after.push_back(out.result.tau1);
        tau2_after.push_back(out.result.tau2);
      }
    }
  }
  // Every solve after the first fault succeeded, and the estimates stay on the truth: with a
  // 2000-tick memory and 0.02 K noise GTLS scatters by a few percent; 10 % bounds every solve.
  EXPECT_EQ(tau1_after.size(), solves_after);
  for (std::size_t i = 0; i < tau1_after.size(); ++i) {
    EXPECT_NEAR(tau1_after[i], kTau1, 0.10 * kTau1) << i;
    EXPECT_NEAR(tau2_after[i], kTau2, 0.10 * kTau2) << i;
  }
}

TEST(FirmwareFaults, AFaultFromTheFirstTickOnlyDelaysTheStart) {
  const uint32_t ticks = 3000;
  const Recording rec = record(ticks, {{2, true, 0, 500}});
  const firmware_config config = calibration(ticks);
  static firmware_state state;
  ASSERT_EQ(firmware_init(&state, &config), DP_STATUS_OK);
  int solved_ok = 0;
  for (uint32_t k = 0; k < ticks; ++k) {
    tick_output out;
    firmware_tick(&state, rec.counts1[k], rec.counts2[k], &out);
    ASSERT_EQ((out.flags & FLAG_CH2_OPEN) != 0, k < 500);
    ASSERT_EQ((out.flags & FLAG_PAUSED) != 0, k < 500 + config.resume_after - 1);
    if ((out.flags & FLAG_SOLVED) && out.result.status == DP_STATUS_OK) ++solved_ok;
  }
  EXPECT_GT(solved_ok, 0);
}

}  // namespace
