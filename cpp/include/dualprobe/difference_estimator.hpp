// Streaming dual-sensor estimator of the paper's eqs. (10)-(12) (Hung et al. 2005):
//   dT2(k) = beta dT1(k) + b2 dT12(k-1),  beta = b2 / b1,
// with dT1(k) = T1(k)-T1(k-1), dT2(k) = T2(k)-T2(k-1), dT12(k-1) = T1(k-1)-T2(k-1).
// update() is O(1): it accumulates the 3x3 scatter of z = [dT1, dT12, dT2]; solve() turns the
// scatter into beta, b1, b2 and the time constants by LS, TLS or GTLS.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <cstddef>

#include "dualprobe/first_order.hpp"
#include "dualprobe/gtls.hpp"
#include "dualprobe/scatter.hpp"
#include "dualprobe/status.hpp"

namespace dualprobe {

template <typename Scalar>
struct DifferenceResult {
  Status status{Status::not_ready};
  Scalar beta{0};
  Scalar b1{0};
  Scalar b2{0};
  Scalar tau1{0};
  Scalar tau2{0};
  // Ratio of the two smallest (generalised) eigenvalues of the scatter: near 0 means a
  // well-defined relation, near 1 means the data do not single one out.
  Scalar eigenvalue_ratio{0};
};

template <typename Scalar>
struct DifferenceConfig {
  Scalar sample_interval{1};
  Method method{Method::gtls};
  Scalar sigma1{0};  // white-noise standard deviation of sensor 1 (GTLS only)
  Scalar sigma2{0};
  Scalar forgetting{1};  // 1 = none; 0.999 forgets with a memory of about 1000 samples

  bool valid() const noexcept {
    const bool interval_ok = sample_interval > Scalar(0) && std::isfinite(sample_interval);
    const bool forgetting_ok = forgetting > Scalar(0) && forgetting <= Scalar(1);
    const bool noise_ok = method != Method::gtls ||
                          (sigma1 > Scalar(0) && sigma2 > Scalar(0) && std::isfinite(sigma1) &&
                           std::isfinite(sigma2));
    const bool method_ok = method == Method::ls || method == Method::tls || method == Method::gtls;
    return interval_ok && forgetting_ok && noise_ok && method_ok;
  }
};

// Noise covariance of z = [dT1(k), dT12(k-1), dT2(k)] for white noise of the given standard
// deviations on T1 and T2 (dT1 and dT12 share e1(k-1), dT12 and dT2 share e2(k-1)).
template <typename Scalar>
Eigen::Matrix<Scalar, 3, 3> difference_noise_covariance(Scalar sigma1, Scalar sigma2) noexcept {
  const Scalar v1 = sigma1 * sigma1;
  const Scalar v2 = sigma2 * sigma2;
  Eigen::Matrix<Scalar, 3, 3> c;
  c << Scalar(2) * v1, -v1, Scalar(0),  //
      -v1, v1 + v2, v2,                 //
      Scalar(0), v2, Scalar(2) * v2;
  return c;
}

// Turns a solved theta = [beta, b2] into the physical parameters, checking feasibility.
template <typename Scalar>
DifferenceResult<Scalar> difference_parameters(Scalar beta, Scalar b2, Scalar ts) noexcept {
  DifferenceResult<Scalar> out;
  out.beta = beta;
  out.b2 = b2;
  out.b1 = b2 / beta;
  const bool feasible = beta > Scalar(0) && b2 > Scalar(0) && b2 < Scalar(1) &&
                        out.b1 > Scalar(0) && out.b1 < Scalar(1) && std::isfinite(out.b1);
  if (!feasible) {
    out.status = Status::infeasible;
    return out;
  }
  out.tau1 = FirstOrderSensor<Scalar>::time_constant_from_b(out.b1, ts);
  out.tau2 = FirstOrderSensor<Scalar>::time_constant_from_b(b2, ts);
  out.status = Status::ok;
  return out;
}

template <typename Scalar>
class DifferenceEstimator {
 public:
  using Config = DifferenceConfig<Scalar>;
  using Result = DifferenceResult<Scalar>;
  using Row = Eigen::Matrix<Scalar, 3, 1>;

  DifferenceEstimator() noexcept = default;

  // On an invalid configuration returns invalid_argument and leaves the estimator as it was.
  Status configure(const Config& config) noexcept {
    if (!config.valid()) return Status::invalid_argument;
    config_ = config;
    reset();
    return Status::ok;
  }

  void reset() noexcept {
    scatter_.reset();
    has_previous_ = false;
  }

  // Forget the previous sample (after a sensor fault) but keep what was accumulated, so the
  // next update starts a new chain of differences instead of spanning the gap.
  void break_chain() noexcept { has_previous_ = false; }

  // One sample pair. A non-finite sample is refused (non_finite_input) and breaks the chain of
  // differences, as update_block does: the accumulated data are kept, but the next sample
  // starts a new chain instead of forming a difference across the refused one (which would
  // span 2 Ts and fit the model with the wrong sample interval).
  Status update(Scalar t1, Scalar t2) noexcept {
    if (!std::isfinite(t1) || !std::isfinite(t2)) {
      has_previous_ = false;
      return Status::non_finite_input;
    }
    if (has_previous_) {
      const Row z(t1 - previous1_, previous1_ - previous2_, t2 - previous2_);
      // Always through lambda: multiplying by 1 is exact, and the branch costs the M4F more
      // than it saves (the ECU budget is 60 instructions per update).
      scatter_.add(z, config_.forgetting);
    }
    previous1_ = t1;
    previous2_ = t2;
    has_previous_ = true;
    return Status::ok;
  }

  // Feeds n samples; equivalent to calling update() on each (same arithmetic in the same
  // order, so the result is bit-identical) but with the scatter held in registers over each
  // run of finite samples. A non-finite sample is refused and breaks the chain of differences
  // so that no difference spans the gap. Returns the number of refused samples.
  std::size_t update_block(const Scalar* t1, const Scalar* t2, std::size_t n) noexcept {
    std::size_t refused = 0;
    std::size_t k = 0;
    while (k < n) {
      if (!std::isfinite(t1[k]) || !std::isfinite(t2[k])) {
        ++refused;
        ++k;
        has_previous_ = false;
        continue;
      }
      // Runs are capped so the accumulation re-reads samples the finiteness scan just
      // brought into cache (one pass over memory instead of two).
      const std::size_t limit = (n - k > kBlock) ? k + kBlock : n;
      std::size_t end = k;
      while (end < limit && std::isfinite(t1[end]) && std::isfinite(t2[end])) ++end;
      accumulate_run(t1 + k, t2 + k, end - k);
      k = end;
    }
    return refused;
  }

  Result solve() const noexcept {
    Result out;
    if (scatter_.weight() < Scalar(2.5)) {  // fewer than three rows cannot fix two unknowns
      out.status = Status::insufficient_excitation;
      return out;
    }
    const auto s = scatter_.matrix();
    EivSolution<Scalar, 3> solution;
    switch (config_.method) {
      case Method::ls: solution = solve_ls<Scalar, 3>(s); break;
      case Method::tls: solution = solve_tls<Scalar, 3>(s); break;
      case Method::gtls:
        solution = solve_gtls<Scalar, 3>(
            s, difference_noise_covariance<Scalar>(config_.sigma1, config_.sigma2));
        break;
    }
    if (solution.status != Status::ok) {
      out.status = solution.status;
      return out;
    }
    out = difference_parameters<Scalar>(solution.theta[0], solution.theta[1],
                                        config_.sample_interval);
    out.eigenvalue_ratio =
        solution.second_smallest > Scalar(0) ? solution.smallest / solution.second_smallest : 0;
    return out;
  }

  const Config& config() const noexcept { return config_; }
  Scalar rows() const noexcept { return scatter_.weight(); }
  Eigen::Matrix<Scalar, 3, 3> scatter() const noexcept { return scatter_.matrix(); }

 private:
  // A run of finite samples; the chain continues from the previous sample when there is one.
  void accumulate_run(const Scalar* t1, const Scalar* t2, std::size_t n) noexcept {
    if (n == 0) return;
    std::size_t start = 0;
    if (!has_previous_) {
      previous1_ = t1[0];
      previous2_ = t2[0];
      has_previous_ = true;
      start = 1;
    }
    if (config_.forgetting < Scalar(1)) {
      for (std::size_t k = start; k < n; ++k) {
        scatter_.add(Row(t1[k] - previous1_, previous1_ - previous2_, t2[k] - previous2_),
                     config_.forgetting);
        previous1_ = t1[k];
        previous2_ = t2[k];
      }
      return;
    }
    // The six scatter entries live in locals so the compiler keeps them in registers; the
    // operations are those of SymmetricScatter::add, in the same order.
    auto& packed = scatter_.packed();
    Scalar s00 = packed[0], s01 = packed[1], s02 = packed[2];
    Scalar s11 = packed[3], s12 = packed[4], s22 = packed[5];
    Scalar p1 = previous1_;
    Scalar p2 = previous2_;
    for (std::size_t k = start; k < n; ++k) {
      const Scalar z0 = t1[k] - p1;
      const Scalar z1 = p1 - p2;
      const Scalar z2 = t2[k] - p2;
      s00 += z0 * z0;
      s01 += z0 * z1;
      s02 += z0 * z2;
      s11 += z1 * z1;
      s12 += z1 * z2;
      s22 += z2 * z2;
      p1 = t1[k];
      p2 = t2[k];
    }
    packed[0] = s00;
    packed[1] = s01;
    packed[2] = s02;
    packed[3] = s11;
    packed[4] = s12;
    packed[5] = s22;
    scatter_.add_weight(Scalar(n - start));
    previous1_ = p1;
    previous2_ = p2;
  }

  static constexpr std::size_t kBlock = 2048;

  SymmetricScatter<Scalar, 3> scatter_{};
  Scalar previous1_{0};
  Scalar previous2_{0};
  Config config_{};
  bool has_previous_{false};
};

// The ECU budget: a float estimator (state and configuration) fits in 128 bytes.
static_assert(sizeof(DifferenceEstimator<float>) <= 128, "float estimator exceeds 128 bytes");
static_assert(sizeof(DifferenceEstimator<double>) <= 192, "double estimator grew unexpectedly");

}  // namespace dualprobe
