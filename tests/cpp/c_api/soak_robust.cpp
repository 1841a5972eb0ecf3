// Float soak of the noise-robust C API (issue 13): 10^8 ticks of the float SVF estimator with
// forgetting (dp_svf_*_f32: float moments, float solve) and the float Kalman reconstruction
// (dp_kalman_*_f32, retuned from every ok solve), on the 100 Hz Pt-100 pair of signals.hpp
// (fluctuating gas with steps, exact first-order sensors, 0.02 K noise). Every 1 % of the run:
//   * the float estimate against a double-precision core SvfFirstOrder<double> (double moments,
//     double solve) fed the same float samples: the time constants agree within 1e-4 (float
//     moments with Kahan block sums keep to a few eps per entry, forgetting bounds old errors;
//     the float solve adds ~1e-6 on this well-conditioned pair: measured 5.5e-6 worst over 10^8
//     ticks, so 1e-4 catches any drift while leaving margin for the conditioning of other
//     windows) and the forgetting-weighted row counts within 1e-3;
//   * both within 15 % of the truth (a 20 s memory, GTLS scatter of a few percent);
//   * the reconstruction's RMSE against the true gas over the last 1 % window within 3x of the
//     first window's, and finite: no drift of the float covariance; the same for the fixed-lag
//     output (DP_KALMAN_MAX_LAG ticks, its second, jump-free filter) against the gas of then.
// Usage: dualprobe_c_api_soak_robust [ticks]   (default 1e8; ctest runs 1e6, `make soak` 1e8)
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "dualprobe/dualprobe.h"
#include "dualprobe/svf_estimator.hpp"
#include "signals.hpp"

namespace {
constexpr double kTau1 = 1.248;
constexpr double kTau2 = 2.895;
constexpr float kForgetting = 0.9995f;
int g_failures = 0;

void check(bool ok, const char* what, long long k, double value, double limit) {
  if (!ok && ++g_failures <= 20) {
    std::printf("FAIL at tick %lld: %s (value %.6g, limit %.6g)\n", k, what, value, limit);
  }
}
}  // namespace

int main(int argc, char** argv) {
  const long long ticks = argc > 1 ? std::atoll(argv[1]) : 100000000LL;
  const long long checkpoint = ticks / 100 > 20000 ? ticks / 100 : 20000;
  const auto started = std::chrono::steady_clock::now();
  dualprobe_test::PairSource source(2025);
  source.tau1 = kTau1;
  source.tau2 = kTau2;
  source.start();

  dp_svf_config_f32 config;
  std::memset(&config, 0, sizeof config);
  config.sample_interval = 0.01f;
  config.filter_time_constant = 0.6f;
  config.order = 1;
  config.sigma1 = config.sigma2 = 0.02f;
  config.forgetting = kForgetting;
  config.max_eigenvalue_ratio = 0.1f;
  dp_svf_instance_f32 svf;
  if (dp_svf_init_f32(&svf, &config) != DP_STATUS_OK) return 2;
  dualprobe::SvfFirstOrder<double> reference;
  dualprobe::SvfConfig<double> rc;
  rc.sample_interval = 0.01f;  // the float values: both see the same Ts, tf, sigma, lambda
  rc.filter_time_constant = 0.6f;
  rc.sigma1 = rc.sigma2 = 0.02f;
  rc.forgetting = kForgetting;
  if (reference.configure(rc) != dualprobe::Status::ok) return 2;

  dp_kalman_config_f32 kc;
  std::memset(&kc, 0, sizeof kc);
  kc.sample_interval = 0.01f;
  kc.order1 = kc.order2 = 1;
  kc.taus1[0] = 1.0f;
  kc.taus2[0] = 3.0f;
  kc.sigma1 = kc.sigma2 = 0.02f;
  kc.intensity = 5.0f;
  kc.window = 8;
  kc.false_alarm = 1e-6f;
  kc.lag = DP_KALMAN_MAX_LAG;  // the fixed-lag filter soaks too
  dp_kalman_instance_f32 kalman;
  if (dp_kalman_init_f32(&kalman, &kc) != DP_STATUS_OK) return 2;

  double worst_tau = 0.0, worst_truth = 0.0, first_rmse = -1.0, worst_rmse_ratio = 0.0;
  double window_sum = 0.0, lag_sum = 0.0, first_lag_rmse = -1.0, worst_lag_ratio = 0.0;
  long long window_count = 0, lag_count = 0, checks = 0;
  double past_gas[DP_KALMAN_MAX_LAG] = {};  // the true gas of the last lag ticks (a ring)
  for (long long k = 1; k <= ticks; ++k) {
    double t1 = 0.0, t2 = 0.0;
    source.next(&t1, &t2);
    const float f1 = float(t1), f2 = float(t2);
    check(dp_svf_update_f32(&svf, f1, f2, 0.0f) == DP_STATUS_OK, "update refused", k, f1, 0);
    reference.update(f1, f2);
    float gas = 0.0f;
    if (dp_kalman_update_f32(&kalman, f1, f2, 1.0f, &gas) == DP_STATUS_OK && k > 1000) {
      window_sum += (gas - source.gas()) * (gas - source.gas());
      ++window_count;
      float lagged = 0.0f;
      if (dp_kalman_lagged_f32(&kalman, &lagged, nullptr) == DP_STATUS_OK) {
        const double then = past_gas[k % DP_KALMAN_MAX_LAG];  // written lag ticks ago
        lag_sum += (lagged - then) * (lagged - then);
        ++lag_count;
      }
    }
    past_gas[k % DP_KALMAN_MAX_LAG] = source.gas();
    if (k % 1000 == 0) {  // the firmware's retune cadence (a solve every 10 s here)
      dp_svf_result_f32 r;
      if (dp_svf_solve_f32(&svf, &r) == DP_STATUS_OK) dp_kalman_retune_f32(&kalman, r.tau1, r.tau2);
    }
    if (k % checkpoint != 0) continue;
    ++checks;
    dp_svf_result_f32 r;
    const dp_status status = dp_svf_solve_f32(&svf, &r);
    const auto d = reference.solve();
    check(status == DP_STATUS_OK && d.status == dualprobe::Status::ok, "solve not ok", k, status, 0);
    if (status == DP_STATUS_OK && d.status == dualprobe::Status::ok) {
      const double e = std::fmax(std::fabs(r.tau1[0] / d.time_constants1[0] - 1.0),
                                 std::fabs(r.tau2[0] / d.time_constants2[0] - 1.0));
      worst_tau = std::fmax(worst_tau, e);
      check(e <= 1e-4, "float tau departs from double", k, e, 1e-4);
      check(std::fabs(r.rows / d.rows - 1.0) <= 1e-3, "row count drifted", k, r.rows / d.rows, 1e-3);
      const double truth = std::fmax(std::fabs(d.time_constants1[0] / kTau1 - 1.0),
                                     std::fabs(d.time_constants2[0] / kTau2 - 1.0));
      const double truth_f = std::fmax(std::fabs(r.tau1[0] / kTau1 - 1.0),
                                       std::fabs(r.tau2[0] / kTau2 - 1.0));
      worst_truth = std::fmax(worst_truth, std::fmax(truth, truth_f));
      check(truth <= 0.15 && truth_f <= 0.15, "estimate far from the truth", k, truth_f, 0.15);
    }
    const double rmse = window_count > 0 ? std::sqrt(window_sum / double(window_count)) : NAN;
    check(std::isfinite(rmse), "reconstruction not finite", k, rmse, 0);
    if (first_rmse < 0.0) first_rmse = rmse;
    worst_rmse_ratio = std::fmax(worst_rmse_ratio, rmse / first_rmse);
    check(rmse <= 3.0 * first_rmse, "reconstruction error grew", k, rmse, 3.0 * first_rmse);
    const double lag_rmse = lag_count > 0 ? std::sqrt(lag_sum / double(lag_count)) : NAN;
    check(std::isfinite(lag_rmse), "fixed-lag output not finite", k, lag_rmse, 0);
    if (first_lag_rmse < 0.0) first_lag_rmse = lag_rmse;
    worst_lag_ratio = std::fmax(worst_lag_ratio, lag_rmse / first_lag_rmse);
    check(lag_rmse <= 3.0 * first_lag_rmse, "fixed-lag error grew", k, lag_rmse,
          3.0 * first_lag_rmse);
    window_sum = 0.0;
    window_count = 0;
    lag_sum = 0.0;
    lag_count = 0;
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  std::printf("%lld ticks, %lld checks, %.1f s; worst |tau_f/tau_d - 1| %.3g (bound 1e-4), "
              "|tau/true - 1| %.3g, reconstruction RMSE / first window %.3g (first %.4g K), "
              "fixed lag %.3g (first %.4g K)\n",
              ticks, checks, seconds, worst_tau, worst_truth, worst_rmse_ratio, first_rmse,
              worst_lag_ratio, first_lag_rmse);
  if (g_failures > 0) std::printf("%d check(s) failed\n", g_failures);
  return g_failures == 0 && checks > 0 ? 0 : 1;
}
