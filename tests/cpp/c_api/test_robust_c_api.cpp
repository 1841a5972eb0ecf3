// The noise-robust C API (issue 13): dp_svf_*_f32 (SVF estimator, flow schedule, float solve)
// and dp_kalman_*_f32 (flow-scheduled causal Kalman), against known truth (simulated sensors
// with flow-dependent time constants), against the double-precision core, and the contract
// (bad input returns a status and leaves the state untouched).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <vector>

#include "dualprobe/dualprobe.h"
#include "dualprobe/kalman.hpp"
#include "dualprobe/svf_estimator.hpp"
#include "signals.hpp"

namespace {

// A pair of sensor chains (sheath -> element, sheath 0 = none) whose time constants follow the
// flow, tau = tau_ref (flow / flow_ref)^-m, seeing a smooth gas; integrated with 20 exact
// sub-steps per sample (constant input and tau per sub-step, taken at its midpoint), which is
// accurate to ~1e-5 relative in the time constants: far below every tolerance below.
struct FlowPair {
  std::vector<float> t1, t2, flow;
  std::vector<double> gas;
};

FlowPair simulate(std::size_t n, double ts, double m, const double taus1[2],
                  const double taus2[2], double noise, std::uint64_t seed, bool flow_varies,
                  double amplitude = 40.0) {
  dualprobe_test::Rng rng(seed);
  FlowPair out;
  const int sub = 20;
  const double h = ts / sub;
  double x[2][2] = {{400.0, 400.0}, {400.0, 400.0}};
  auto gas_at = [&](double t) {
    return 400.0 + amplitude * (0.5 * std::sin(0.31 * t) + 0.3 * std::sin(1.7 * t + 1.0) +
                                0.2 * std::sin(0.07 * t + 2.0) + 0.15 * std::sin(3.9 * t));
  };
  auto ratio_at = [&](double t) {
    return flow_varies ? std::exp(0.8 * std::sin(0.11 * t) + 0.3 * std::sin(0.53 * t)) : 1.0;
  };
  const double* taus[2] = {taus1, taus2};
  for (int i = 0; i < 2; ++i) x[i][0] = x[i][1] = gas_at(0.0);
  for (std::size_t k = 0; k < n; ++k) {
    const double t = double(k) * ts;
    out.gas.push_back(gas_at(t));
    out.flow.push_back(float(20.0 * ratio_at(t)));
    out.t1.push_back(float(x[0][1] + noise * rng.normal()));
    out.t2.push_back(float(x[1][1] + noise * rng.normal()));
    for (int s = 0; s < sub; ++s) {
      const double mid = t + (s + 0.5) * h;
      const double phi = std::pow(ratio_at(mid), -m);
      const double g = gas_at(mid);
      for (int i = 0; i < 2; ++i) {
        const double sheath = taus[i][1] * phi;
        const double element = taus[i][0] * phi;
        const double input = sheath > 0.0 ? x[i][0] : g;
        if (sheath > 0.0) x[i][0] = g + (x[i][0] - g) * std::exp(-h / sheath);
        const double drive = sheath > 0.0 ? 0.5 * (input + x[i][0]) : g;
        x[i][1] = drive + (x[i][1] - drive) * std::exp(-h / element);
      }
    }
  }
  return out;
}

dp_svf_config_f32 svf_config(uint32_t order, float flow_ref, float forgetting = 1.0f) {
  dp_svf_config_f32 c;
  std::memset(&c, 0, sizeof c);
  c.sample_interval = 0.01f;
  c.filter_time_constant = 0.6f;
  c.order = order;
  c.sigma1 = 0.02f;
  c.sigma2 = 0.02f;
  c.quantisation = 6e-5f;
  c.forgetting = forgetting;
  c.flow_ref = flow_ref;
  c.exponent = 0.5f;
  c.max_eigenvalue_ratio = 0.1f;
  return c;
}

dp_svf_result_f32 run_svf(const dp_svf_config_f32& config, const FlowPair& data) {
  dp_svf_instance_f32 svf;
  EXPECT_EQ(dp_svf_init_f32(&svf, &config), DP_STATUS_OK);
  dp_svf_result_f32 result;
  for (std::size_t k = 0; k < data.t1.size(); ++k) {
    EXPECT_EQ(dp_svf_update_f32(&svf, data.t1[k], data.t2[k], data.flow[k]), DP_STATUS_OK);
    // Order 2 with flow refines phi's exponent with every ok solve (as the firmware does).
    if ((k + 1) % 2000 == 0) (void)dp_svf_solve_f32(&svf, &result);
  }
  dp_svf_solve_f32(&svf, &result);
  return result;
}

// First-order sensors, flow-dependent (m = 0.45), 0.02 K noise, 100 Hz, 200 s: the flow
// basis identifies tau_ref exactly up to noise and the exponent through the log-log fit.
// Tolerances: the noise spread of the estimates over seeds is ~0.3 % (tau) and ~0.01 (m) at
// this record length; 1.5 % and 0.03 leave room for the float solve without hiding a bias of
// the basis (an unscheduled fit of the same data is off by > 10 %, checked below).
TEST(RobustCApi, FirstOrderFlowScheduleRecoversTauRefAndExponent) {
  const double taus1[2] = {1.2, 0.0};
  const double taus2[2] = {3.0, 0.0};
  const FlowPair data = simulate(20000, 0.01, 0.45, taus1, taus2, 0.02, 11, true);
  const dp_svf_result_f32 r = run_svf(svf_config(1, 20.0f), data);
  ASSERT_EQ(r.status, DP_STATUS_OK);
  EXPECT_NEAR(r.tau1[0], 1.2, 0.015 * 1.2);
  EXPECT_NEAR(r.tau2[0], 3.0, 0.015 * 3.0);
  EXPECT_NEAR(r.exponent, 0.45, 0.03);
  EXPECT_LT(r.eigenvalue_ratio, 0.1f);
  // The same data without the schedule: a constant tau cannot explain them; the fit is off
  // by several percent (seen 7.5 % and 2 %, summed 9.5 %), ten times the scheduled error.
  const dp_svf_result_f32 plain = run_svf(svf_config(1, 0.0f), data);
  if (plain.status == DP_STATUS_OK) {
    EXPECT_GT(std::fabs(plain.tau2[0] / 3.0 - 1.0) + std::fabs(plain.tau1[0] / 1.2 - 1.0), 0.05);
  }
}

// Sheathed (two-stage) sensors, both stages following the flow: order 2 with the schedule.
// The sheath stages are the hard part (0.15 / 0.3 s under 1.2 / 3 s); 3 % and 0.05 in m hold
// with margin over seeds on this 300 s record (seen: <= 1 %, 0.01).
TEST(RobustCApi, SecondOrderFlowScheduleRecoversSheathAndElement) {
  const double taus1[2] = {1.2, 0.15};
  const double taus2[2] = {3.0, 0.3};
  const FlowPair data = simulate(30000, 0.01, 0.5, taus1, taus2, 0.02, 12, true);
  const dp_svf_result_f32 r = run_svf(svf_config(2, 20.0f), data);
  ASSERT_EQ(r.status, DP_STATUS_OK);
  EXPECT_NEAR(r.tau1[0], 1.2, 0.03 * 1.2);
  EXPECT_NEAR(r.tau1[1], 0.15, 0.03 * 0.15);
  EXPECT_NEAR(r.tau2[0], 3.0, 0.03 * 3.0);
  EXPECT_NEAR(r.tau2[1], 0.3, 0.03 * 0.3);
  EXPECT_NEAR(r.exponent, 0.5, 0.05);
}

// Without flow, order 1, constant time constants: the float C API (float moments, float
// solve) against the double core on the same samples. The estimates are within their noise
// spread (~0.3 %) of each other; float rounding contributes far less (1e-3 relative bound).
TEST(RobustCApi, NoFlowMatchesTheDoubleCore) {
  const double taus1[2] = {1.248, 0.0};
  const double taus2[2] = {2.895, 0.0};
  const FlowPair data = simulate(20000, 0.01, 0.0, taus1, taus2, 0.02, 13, false);
  const dp_svf_result_f32 r = run_svf(svf_config(1, 0.0f), data);
  ASSERT_EQ(r.status, DP_STATUS_OK);
  dualprobe::SvfFirstOrder<double> core;
  dualprobe::SvfConfig<double> c;
  c.sample_interval = 0.01;
  c.filter_time_constant = 0.6;
  c.sigma1 = c.sigma2 = std::sqrt(0.02 * 0.02 + 6e-5 * 6e-5 / 12.0);
  ASSERT_EQ(core.configure(c), dualprobe::Status::ok);
  for (std::size_t k = 0; k < data.t1.size(); ++k) core.update(data.t1[k], data.t2[k]);
  const auto d = core.solve();
  ASSERT_EQ(d.status, dualprobe::Status::ok);
  EXPECT_NEAR(r.tau1[0] / d.time_constants1[0], 1.0, 1e-3);
  EXPECT_NEAR(r.tau2[0] / d.time_constants2[0], 1.0, 1e-3);
  EXPECT_NEAR(r.tau1[0], 1.248, 0.01 * 1.248);  // and both at the truth
  EXPECT_NEAR(r.tau2[0], 2.895, 0.01 * 2.895);
}

TEST(RobustCApi, SvfContract) {
  dp_svf_instance_f32 svf;
  dp_svf_config_f32 bad = svf_config(3, 0.0f);
  EXPECT_EQ(dp_svf_init_f32(&svf, &bad), DP_STATUS_INVALID_ARGUMENT);
  EXPECT_EQ(dp_svf_update_f32(&svf, 1.0f, 2.0f, 1.0f), DP_STATUS_INVALID_ARGUMENT);
  dp_svf_result_f32 r;
  EXPECT_EQ(dp_svf_solve_f32(&svf, &r), DP_STATUS_INVALID_ARGUMENT);
  bad = svf_config(1, -1.0f);
  EXPECT_EQ(dp_svf_init_f32(&svf, &bad), DP_STATUS_INVALID_ARGUMENT);
  bad = svf_config(1, 0.0f, 1.5f);
  EXPECT_EQ(dp_svf_init_f32(&svf, &bad), DP_STATUS_INVALID_ARGUMENT);
  EXPECT_EQ(dp_svf_init_f32(nullptr, &bad), DP_STATUS_INVALID_ARGUMENT);
  EXPECT_EQ(dp_svf_init_f32(&svf, nullptr), DP_STATUS_INVALID_ARGUMENT);

  // Bad samples leave the state untouched: the solve after them is bit-identical.
  const double taus1[2] = {1.2, 0.0};
  const double taus2[2] = {3.0, 0.0};
  const FlowPair data = simulate(6000, 0.01, 0.5, taus1, taus2, 0.02, 14, true);
  const dp_svf_config_f32 config = svf_config(1, 20.0f);
  dp_svf_instance_f32 a;
  dp_svf_instance_f32 b;
  ASSERT_EQ(dp_svf_init_f32(&a, &config), DP_STATUS_OK);
  ASSERT_EQ(dp_svf_init_f32(&b, &config), DP_STATUS_OK);
  const float nan = std::nanf("");
  for (std::size_t k = 0; k < data.t1.size(); ++k) {
    ASSERT_EQ(dp_svf_update_f32(&a, data.t1[k], data.t2[k], data.flow[k]), DP_STATUS_OK);
    ASSERT_EQ(dp_svf_update_f32(&b, data.t1[k], data.t2[k], data.flow[k]), DP_STATUS_OK);
    if (k % 500 == 7) {
      EXPECT_EQ(dp_svf_update_f32(&b, nan, data.t2[k], data.flow[k]), DP_STATUS_NON_FINITE_INPUT);
      EXPECT_EQ(dp_svf_update_f32(&b, data.t1[k], data.t2[k], nan), DP_STATUS_NON_FINITE_INPUT);
      EXPECT_EQ(dp_svf_update_f32(&b, data.t1[k], data.t2[k], 0.0f), DP_STATUS_INVALID_ARGUMENT);
      EXPECT_EQ(dp_svf_update_f32(&b, data.t1[k], data.t2[k], -3.0f),
                DP_STATUS_INVALID_ARGUMENT);
    }
  }
  dp_svf_result_f32 ra;
  dp_svf_result_f32 rb;
  EXPECT_EQ(dp_svf_solve_f32(&a, &ra), DP_STATUS_OK);
  EXPECT_EQ(dp_svf_solve_f32(&b, &rb), DP_STATUS_OK);
  EXPECT_EQ(std::memcmp(&ra, &rb, sizeof ra), 0);
  EXPECT_EQ(dp_svf_solve_f32(&a, nullptr), DP_STATUS_INVALID_ARGUMENT);
  // The schedule of a result: (flow/flow_ref)^m, 1 for a refused result.
  EXPECT_NEAR(dp_svf_schedule_f32(&a, &ra, 40.0f), std::pow(2.0f, ra.exponent), 1e-5f);
  dp_svf_result_f32 refused = ra;
  refused.status = DP_STATUS_INFEASIBLE;
  EXPECT_EQ(dp_svf_schedule_f32(&a, &refused, 40.0f), 1.0f);
}

// No excitation (a constant gas, noise only): never an ok result.
TEST(RobustCApi, NoExcitationIsNeverPublished) {
  dp_svf_instance_f32 svf;
  const dp_svf_config_f32 config = svf_config(1, 0.0f, 0.9995f);
  ASSERT_EQ(dp_svf_init_f32(&svf, &config), DP_STATUS_OK);
  dualprobe_test::Rng rng(15);
  dp_svf_result_f32 r;
  for (int k = 0; k < 20000; ++k) {
    dp_svf_update_f32(&svf, float(400.0 + 0.02 * rng.normal()), float(400.0 + 0.02 * rng.normal()),
                      0.0f);
    if (k % 100 == 99) {
      EXPECT_NE(dp_svf_solve_f32(&svf, &r), DP_STATUS_OK) << "tick " << k;
    }
  }
}

// A gap (fault) in the middle of a record: with dp_svf_break_chain_f32 the estimate after the
// gap is as accurate as without the gap (within the noise spread, 1.5 %).
TEST(RobustCApi, BreakChainKeepsTheEstimateAcrossAGap) {
  const double taus1[2] = {1.2, 0.0};
  const double taus2[2] = {3.0, 0.0};
  const FlowPair data = simulate(30000, 0.01, 0.5, taus1, taus2, 0.02, 16, true);
  const dp_svf_config_f32 config = svf_config(1, 20.0f);
  dp_svf_instance_f32 svf;
  ASSERT_EQ(dp_svf_init_f32(&svf, &config), DP_STATUS_OK);
  for (std::size_t k = 0; k < data.t1.size(); ++k) {
    if (k >= 12000 && k < 12300) continue;  // the faulted ticks
    if (k == 12300) dp_svf_break_chain_f32(&svf);
    ASSERT_EQ(dp_svf_update_f32(&svf, data.t1[k], data.t2[k], data.flow[k]), DP_STATUS_OK);
  }
  dp_svf_result_f32 r;
  ASSERT_EQ(dp_svf_solve_f32(&svf, &r), DP_STATUS_OK);
  EXPECT_NEAR(r.tau1[0], 1.2, 0.015 * 1.2);
  EXPECT_NEAR(r.tau2[0], 3.0, 0.015 * 3.0);
}

dp_kalman_config_f32 kalman_config(uint32_t order, float tau1, float tau2, float q) {
  dp_kalman_config_f32 c;
  std::memset(&c, 0, sizeof c);
  c.sample_interval = 0.01f;
  c.order1 = c.order2 = order;
  c.taus1[0] = tau1;
  c.taus2[0] = tau2;
  c.taus1[1] = 0.15f;
  c.taus2[1] = 0.3f;
  c.sigma1 = c.sigma2 = 0.02f;
  c.quantisation = 6e-5f;
  c.intensity = q;
  c.window = 8;
  c.false_alarm = 1e-6f;
  return c;
}

double rmse_after(const std::vector<double>& a, const std::vector<double>& b, std::size_t from) {
  double sum = 0.0;
  for (std::size_t k = from; k < a.size(); ++k) sum += (a[k] - b[k]) * (a[k] - b[k]);
  return std::sqrt(sum / double(a.size() - from));
}

// Constant time constants (psi = 1): the C API's per-interval closed-form model against the
// core Kalman with its exact (Van Loan, double) discretisation, both fed the same samples. Phi
// is exact in both; the C API's process noise uses the midpoint rule, so the two filters differ
// by a small change of gain: their outputs agree to 2 % of the reconstruction error itself.
TEST(RobustCApi, KalmanMatchesTheCoreWithConstantTimeConstants) {
  const double taus1[2] = {1.2, 0.0};
  const double taus2[2] = {3.0, 0.0};
  const FlowPair data = simulate(6000, 0.01, 0.0, taus1, taus2, 0.02, 17, false);
  const float q = 20.0f;
  dp_kalman_instance_f32 k;
  const dp_kalman_config_f32 config = kalman_config(1, 1.2f, 3.0f, q);
  ASSERT_EQ(dp_kalman_init_f32(&k, &config), DP_STATUS_OK);
  dualprobe::KalmanFirstOrder<double, 16> core;
  dualprobe::KalmanConfig<double> cc;
  cc.sample_interval = 0.01;
  cc.taus1[0] = 1.2;
  cc.taus2[0] = 3.0;
  cc.sigma1 = cc.sigma2 = std::sqrt(0.02 * 0.02 + 6e-5 * 6e-5 / 12.0);
  cc.intensity = q;
  cc.window = 8;
  ASSERT_EQ(core.configure(cc), dualprobe::Status::ok);
  std::vector<double> ours, theirs;
  for (std::size_t i = 0; i < data.t1.size(); ++i) {
    float gas = 0.0f;
    double reference = 0.0;
    ASSERT_EQ(dp_kalman_update_f32(&k, data.t1[i], data.t2[i], 1.0f, &gas), DP_STATUS_OK);
    ASSERT_EQ(core.update(data.t1[i], data.t2[i], &reference), dualprobe::Status::ok);
    ours.push_back(gas);
    theirs.push_back(reference);
  }
  const double error = rmse_after(theirs, data.gas, 500);
  EXPECT_LT(rmse_after(ours, theirs, 500), 0.02 * error + 1e-3);
  EXPECT_LT(rmse_after(ours, data.gas, 500), 1.05 * error);
}

// Flow-dependent time constants: the scheduled Kalman (psi = (flow/flow_ref)^m per sample)
// against the same filter held at psi = 1. Two-stage sensors, order-2 filter. The schedule
// must pay: an RMSE at most 0.7 of the unscheduled filter's (seen 0.57: much of the error on
// this fast gas is the causal lag, which no schedule removes), and far below the raw fast
// sensor's (at most a third).
TEST(RobustCApi, ScheduledKalmanFollowsFlowDependentSensors) {
  const double taus1[2] = {1.2, 0.15};
  const double taus2[2] = {3.0, 0.3};
  const FlowPair data = simulate(12000, 0.01, 0.5, taus1, taus2, 0.02, 18, true);
  const dp_kalman_config_f32 config = kalman_config(2, 1.2f, 3.0f, 20.0f);
  dp_kalman_instance_f32 scheduled;
  dp_kalman_instance_f32 fixed;
  ASSERT_EQ(dp_kalman_init_f32(&scheduled, &config), DP_STATUS_OK);
  ASSERT_EQ(dp_kalman_init_f32(&fixed, &config), DP_STATUS_OK);
  std::vector<double> a, b, raw;
  for (std::size_t i = 0; i < data.t1.size(); ++i) {
    float ga = 0.0f;
    float gb = 0.0f;
    const float psi = std::sqrt(data.flow[i] / 20.0f);
    ASSERT_EQ(dp_kalman_update_f32(&scheduled, data.t1[i], data.t2[i], psi, &ga), DP_STATUS_OK);
    ASSERT_EQ(dp_kalman_update_f32(&fixed, data.t1[i], data.t2[i], 1.0f, &gb), DP_STATUS_OK);
    a.push_back(ga);
    b.push_back(gb);
    raw.push_back(data.t1[i]);
  }
  const double with = rmse_after(a, data.gas, 500);
  const double without = rmse_after(b, data.gas, 500);
  const double sensor = rmse_after(raw, data.gas, 500);
  std::printf("scheduled %.4g K, unscheduled %.4g K, raw fast sensor %.4g K\n", with, without,
              sensor);
  EXPECT_LT(with, 0.7 * without);
  EXPECT_LT(3.0 * with, sensor);
}

// The fixed-lag output on the same flow-scheduled pair: the gas at t_{k-lag} against the truth
// there, beside the causal output at t_k. A lag of 0.15 s (an eighth of the faster element's
// time constant) must recover most of what causality costs: at most half the causal RMSE.
TEST(RobustCApi, KalmanFixedLagBeatsTheCausalOutput) {
  const double taus1[2] = {1.2, 0.15};
  const double taus2[2] = {3.0, 0.3};
  const FlowPair data = simulate(12000, 0.01, 0.5, taus1, taus2, 0.02, 18, true);
  dp_kalman_config_f32 config = kalman_config(2, 1.2f, 3.0f, 20.0f);
  config.lag = 15;
  dp_kalman_instance_f32 k;
  ASSERT_EQ(dp_kalman_init_f32(&k, &config), DP_STATUS_OK);
  std::vector<double> causal, lagged, truth_now, truth_then;
  for (std::size_t i = 0; i < data.t1.size(); ++i) {
    float gas = 0.0f;
    const float psi = std::sqrt(data.flow[i] / 20.0f);
    ASSERT_EQ(dp_kalman_update_f32(&k, data.t1[i], data.t2[i], psi, &gas), DP_STATUS_OK);
    float back = -1.0f;
    float sd = -1.0f;
    const dp_status status = dp_kalman_lagged_f32(&k, &back, &sd);
    if (i < 15) {
      ASSERT_EQ(status, DP_STATUS_NOT_READY);
      EXPECT_EQ(back, -1.0f);
      continue;
    }
    ASSERT_EQ(status, DP_STATUS_OK);
    ASSERT_TRUE(std::isfinite(back) && sd >= 0.0f);
    causal.push_back(gas);
    truth_now.push_back(data.gas[i]);
    lagged.push_back(back);
    truth_then.push_back(data.gas[i - 15]);
  }
  const double c = rmse_after(causal, truth_now, 500);
  const double l = rmse_after(lagged, truth_then, 500);
  std::printf("causal %.4g K, fixed lag 0.15 s %.4g K\n", c, l);
  EXPECT_LT(l, 0.5 * c);
}

TEST(RobustCApi, KalmanContract) {
  dp_kalman_instance_f32 k;
  dp_kalman_config_f32 bad = kalman_config(3, 1.2f, 3.0f, 1.0f);
  EXPECT_EQ(dp_kalman_init_f32(&k, &bad), DP_STATUS_INVALID_ARGUMENT);
  float gas = 123.0f;
  EXPECT_EQ(dp_kalman_update_f32(&k, 1.0f, 1.0f, 1.0f, &gas), DP_STATUS_INVALID_ARGUMENT);
  bad = kalman_config(1, -1.0f, 3.0f, 1.0f);
  EXPECT_EQ(dp_kalman_init_f32(&k, &bad), DP_STATUS_INVALID_ARGUMENT);
  bad = kalman_config(1, 1.0f, 3.0f, 0.0f);
  EXPECT_EQ(dp_kalman_init_f32(&k, &bad), DP_STATUS_INVALID_ARGUMENT);
  bad = kalman_config(1, 1.0f, 3.0f, 1.0f);
  bad.window = DP_KALMAN_MAX_WINDOW + 1;
  EXPECT_EQ(dp_kalman_init_f32(&k, &bad), DP_STATUS_INVALID_ARGUMENT);
  bad = kalman_config(1, 1.0f, 3.0f, 1.0f);
  bad.lag = DP_KALMAN_MAX_LAG + 1;
  EXPECT_EQ(dp_kalman_init_f32(&k, &bad), DP_STATUS_INVALID_ARGUMENT);
  EXPECT_EQ(dp_kalman_lagged_f32(&k, &gas, nullptr), DP_STATUS_NOT_READY);
  EXPECT_EQ(dp_kalman_lagged_f32(nullptr, &gas, nullptr), DP_STATUS_INVALID_ARGUMENT);

  dp_kalman_config_f32 config = kalman_config(2, 1.2f, 3.0f, 1.0f);
  config.lag = 5;
  dp_kalman_instance_f32 a;
  dp_kalman_instance_f32 b;
  ASSERT_EQ(dp_kalman_init_f32(&a, &config), DP_STATUS_OK);
  ASSERT_EQ(dp_kalman_init_f32(&b, &config), DP_STATUS_OK);
  const float nan = std::nanf("");
  const float good1[2] = {1.3f, 0.1f};
  const float good2[2] = {2.9f, 0.2f};
  const float bad_taus[2] = {0.0f, 0.1f};
  for (int i = 0; i < 500; ++i) {
    const float t1 = 400.0f + 0.1f * float(i % 17);
    const float t2 = 400.0f + 0.05f * float(i % 23);
    float ga = 0.0f;
    float gb = 0.0f;
    if (i == 100) {
      ASSERT_EQ(dp_kalman_retune_f32(&a, good1, good2), DP_STATUS_OK);
      ASSERT_EQ(dp_kalman_retune_f32(&b, good1, good2), DP_STATUS_OK);
      EXPECT_EQ(dp_kalman_retune_f32(&b, bad_taus, good2), DP_STATUS_INVALID_ARGUMENT);
    }
    if (i % 50 == 3) {
      gb = 7.0f;
      EXPECT_EQ(dp_kalman_update_f32(&b, nan, t2, 1.0f, &gb), DP_STATUS_NON_FINITE_INPUT);
      EXPECT_EQ(dp_kalman_update_f32(&b, t1, t2, nan, &gb), DP_STATUS_NON_FINITE_INPUT);
      EXPECT_EQ(dp_kalman_update_f32(&b, t1, t2, 0.0f, &gb), DP_STATUS_INVALID_ARGUMENT);
      EXPECT_EQ(dp_kalman_update_f32(&b, t1, t2, 1.0f, nullptr), DP_STATUS_INVALID_ARGUMENT);
      EXPECT_EQ(gb, 7.0f);
    }
    ASSERT_EQ(dp_kalman_update_f32(&a, t1, t2, 1.1f, &ga), DP_STATUS_OK);
    ASSERT_EQ(dp_kalman_update_f32(&b, t1, t2, 1.1f, &gb), DP_STATUS_OK);
    ASSERT_EQ(ga, gb) << "sample " << i;  // untouched: bit-identical
    float la = 0.0f;
    float lb = 0.0f;
    ASSERT_EQ(dp_kalman_lagged_f32(&a, &la, nullptr), dp_kalman_lagged_f32(&b, &lb, nullptr));
    ASSERT_EQ(la, lb) << "sample " << i;
  }
}

}  // namespace
