// Float robustness soak (issue 4): 10^8 updates of the float C API estimator with forgetting
// on a realistic signal (100 Hz Pt-100 pair, fluctuating gas with steps, 0.02 K noise),
// checked every 1 % of the run against a double-precision core estimator fed the same
// samples: no NaN, no drift (the float scatter stays within its rounding bound of the double
// one, the effective row count stays at sum lambda^i), positive definite scatter, and time
// constants that agree with double within what the conditioning allows.
//
// Usage: dualprobe_c_api_soak [updates]   (default 1e8; the sanitizer build runs fewer)
#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>

#include "dualprobe/difference_estimator.hpp"
#include "dualprobe/dualprobe.h"
#include "signals.hpp"

namespace {

constexpr double kTau1 = 1.248;
constexpr double kTau2 = 2.895;
constexpr float kForgetting = 0.9995f;
constexpr double kEps = std::numeric_limits<float>::epsilon();

int g_failures = 0;

void check(bool ok, const char* what, long long k, double value, double limit) {
  if (!ok) {
    ++g_failures;
    if (g_failures <= 20) {
      std::printf("FAIL at update %lld: %s (value %.6g, limit %.6g)\n", k, what, value, limit);
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  const long long updates = argc > 1 ? std::atoll(argv[1]) : 100000000LL;
  const long long checkpoint = updates / 100 > 10000 ? updates / 100 : 10000;
  const auto started = std::chrono::steady_clock::now();

  dualprobe_test::PairSource source(2024);
  source.tau1 = kTau1;
  source.tau2 = kTau2;
  source.start();

  dp_diff_instance_f32 estimator;
  const dp_diff_config_f32 config = {0.01f, DP_METHOD_GTLS, 0.02f, 0.02f, kForgetting};
  if (dp_diff_init_f32(&estimator, &config) != DP_STATUS_OK) return 2;
  dualprobe::DifferenceEstimator<double> reference;
  dualprobe::DifferenceConfig<double> rc;
  rc.sample_interval = 0.01f;  // the float value, so both see the same Ts
  rc.method = dualprobe::Method::gtls;
  rc.sigma1 = 0.02f;
  rc.sigma2 = 0.02f;
  rc.forgetting = kForgetting;
  if (reference.configure(rc) != dualprobe::Status::ok) return 2;

  double worst_scatter = 0.0, worst_tau = 0.0, worst_truth = 0.0;
  long long checks = 0;
  for (long long k = 1; k <= updates; ++k) {
    double t1 = 0.0, t2 = 0.0;
    source.next(&t1, &t2);
    const float f1 = static_cast<float>(t1), f2 = static_cast<float>(t2);
    if (dp_diff_update_f32(&estimator, f1, f2) != DP_STATUS_OK) {
      check(false, "update refused a finite sample", k, f1, 0);
    }
    reference.update(f1, f2);
    if (k % checkpoint != 0) continue;
    ++checks;

    float packed[6];
    dp_diff_scatter_f32(&estimator, packed);
    Eigen::Matrix3d s;
    s << packed[0], packed[1], packed[2], packed[1], packed[3], packed[4], packed[2], packed[4],
        packed[5];
    const Eigen::Matrix3d d = reference.scatter();
    check(s.allFinite(), "scatter not finite", k, 0, 0);
    // Positive definite (the noise alone makes every direction excited).
    const double smallest = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(s).eigenvalues()[0];
    check(smallest > 0.0 && Eigen::LLT<Eigen::Matrix3d>(s).info() == Eigen::Success,
          "scatter lost positive definiteness", k, smallest, 0);
    // Drift: each update rounds every entry once (relative eps) and forgetting damps old
    // errors by lambda per step, so the float error stays below eps / (1 - lambda) of the
    // scatter's size for ever (2 eps: the product and the sum).
    const double relative = (s - d).norm() / d.norm();
    const double scatter_bound = 2.0 * kEps / (1.0 - kForgetting);
    worst_scatter = std::max(worst_scatter, relative);
    check(relative <= scatter_bound, "float scatter drifted from double", k, relative,
          scatter_bound);
    const double rows = dp_diff_rows_f32(&estimator);
    // k samples give k - 1 rows: sum of lambda^i for i < k - 1.
    const double lambda = kForgetting;
    const double rows_expected = (1.0 - std::pow(lambda, static_cast<double>(k - 1))) / (1.0 - lambda);
    // Same bound on the effective row count (a scalar fixed point of w = lambda w + 1).
    check(std::abs(rows / rows_expected - 1.0) <= scatter_bound, "row count drifted", k,
          rows / rows_expected - 1.0, scatter_bound);

    dp_diff_result_f32 r;
    dp_diff_solve_f32(&estimator, &r);
    const auto rd = reference.solve();
    check(r.status == DP_STATUS_OK, "float solve not ok", k, r.status, 0);
    if (r.status != DP_STATUS_OK || rd.status != dualprobe::Status::ok) continue;
    check(std::isfinite(r.tau1) && std::isfinite(r.tau2), "non-finite tau", k, r.tau1, 0);
    // First-order perturbation of the generalised eigenvector: |d theta| ~ |dS| / gap, with
    // dS the measured scatter difference plus the solve's own rounding (8 eps); the
    // conditioning lambda_max / gap of the whitened scatter turns it into a relative bound.
    const Eigen::Matrix3d c = dualprobe::difference_noise_covariance<double>(0.02f, 0.02f);
    const Eigen::Matrix3d l_inv = c.llt().matrixL().solve(Eigen::Matrix3d::Identity());
    const Eigen::Vector3d mu =
        Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(l_inv * d * l_inv.transpose()).eigenvalues();
    const double condition = mu[2] / (mu[1] - mu[0]);
    const double tau_bound = 4.0 * (relative + 8.0 * kEps) * condition;
    const double tau_error = std::max(std::abs(r.tau1 / rd.tau1 - 1.0), std::abs(r.tau2 / rd.tau2 - 1.0));
    worst_tau = std::max(worst_tau, tau_error / tau_bound);
    check(tau_error <= tau_bound, "float tau departs from double beyond conditioning", k,
          tau_error, tau_bound);
    // The physics: a 20 s memory of a fluctuating gas identifies both sensors; GTLS is
    // consistent, its scatter at 0.02 K noise is a few percent (15 % bounds every checkpoint).
    const double truth_error = std::max(std::abs(rd.tau1 / kTau1 - 1.0), std::abs(rd.tau2 / kTau2 - 1.0));
    worst_truth = std::max(worst_truth, truth_error);
    check(truth_error <= 0.15, "estimate far from the true time constants", k, truth_error, 0.15);
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  std::printf("%lld updates, %lld checks, %.1f s; worst: scatter %.3g (bound %.3g), "
              "tau/bound %.3g, |tau/true - 1| %.3g\n",
              updates, checks, seconds, worst_scatter, 2.0 * kEps / (1.0 - kForgetting), worst_tau,
              worst_truth);
  if (g_failures > 0) std::printf("%d check(s) failed\n", g_failures);
  return g_failures == 0 && checks > 0 ? 0 : 1;
}
