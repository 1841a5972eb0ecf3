// Gas-temperature reconstruction by the exact inverse of the first-order model (paper, end of
// section III), from sensor 1, sensor 2, or their weighted combination, with an optional
// first-order low-pass that bounds the noise gain (the bare inverse multiplies white noise by
// about sqrt(2) tau / Ts).
#pragma once

#include <cmath>
#include <cstddef>
#include <limits>

#include "dualprobe/first_order.hpp"
#include "dualprobe/status.hpp"

namespace dualprobe {

enum class ReconstructionSource : int { sensor1 = 0, sensor2 = 1, weighted = 2 };

// Weight of sensor 1 in the combination: inverse-variance weights, since the inverse's noise
// gain grows with tau (w = tau2^2 / (tau1^2 + tau2^2) for equal sensor noise).
template <typename Scalar>
Scalar sensor1_weight(Scalar tau1, Scalar tau2) noexcept {
  return tau2 * tau2 / (tau1 * tau1 + tau2 * tau2);
}

// Batch exact inverse: out[k-1] = Tg(k-1) from temps[k-1], temps[k]; out[n-1] = NaN (no later
// sample). `out` must hold n values and may not alias `temps`.
template <typename Scalar>
Status reconstruct_inverse(const Scalar* temps, std::size_t n, Scalar tau, Scalar ts,
                           Scalar* out) noexcept {
  FirstOrderSensor<Scalar> sensor;
  if (!sensor.set_time_constant(tau, ts)) return Status::invalid_argument;
  if (n == 0) return Status::ok;
  for (std::size_t k = 1; k < n; ++k) out[k - 1] = sensor.inverse(temps[k], temps[k - 1]);
  out[n - 1] = std::numeric_limits<Scalar>::quiet_NaN();
  return Status::ok;
}

// Streaming reconstruction, one gas value per sample pair.
template <typename Scalar>
class InverseReconstructor {
 public:
  struct Config {
    Scalar sample_interval{1};
    Scalar tau1{1};
    Scalar tau2{1};
    ReconstructionSource source{ReconstructionSource::weighted};
    Scalar lowpass_tau{0};  // 0 = no low-pass stage
  };

  Status configure(const Config& config) noexcept {
    FirstOrderSensor<Scalar> s1;
    FirstOrderSensor<Scalar> s2;
    const bool lowpass_ok = config.lowpass_tau >= Scalar(0) && std::isfinite(config.lowpass_tau);
    if (!s1.set_time_constant(config.tau1, config.sample_interval) ||
        !s2.set_time_constant(config.tau2, config.sample_interval) || !lowpass_ok) {
      return Status::invalid_argument;
    }
    sensor1_ = s1;
    sensor2_ = s2;
    config_ = config;
    switch (config.source) {
      case ReconstructionSource::sensor1: weight1_ = Scalar(1); break;
      case ReconstructionSource::sensor2: weight1_ = Scalar(0); break;
      case ReconstructionSource::weighted: weight1_ = sensor1_weight(config.tau1, config.tau2); break;
    }
    lowpass_pole_ = config.lowpass_tau > Scalar(0)
                        ? std::exp(-config.sample_interval / config.lowpass_tau)
                        : Scalar(0);
    reset();
    return Status::ok;
  }

  void reset() noexcept {
    has_previous_ = false;
    has_output_ = false;
  }

  // Consumes T1(k), T2(k); on ok writes the gas temperature over [k-1, k) to *gas. The first
  // sample only primes the state and returns not_ready.
  Status update(Scalar t1, Scalar t2, Scalar* gas) noexcept {
    if (!std::isfinite(t1) || !std::isfinite(t2)) return Status::non_finite_input;
    if (!has_previous_) {
      previous1_ = t1;
      previous2_ = t2;
      has_previous_ = true;
      return Status::not_ready;
    }
    const Scalar g1 = sensor1_.inverse(t1, previous1_);
    const Scalar g2 = sensor2_.inverse(t2, previous2_);
    const Scalar raw = weight1_ * g1 + (Scalar(1) - weight1_) * g2;
    // The low-pass starts from its first input so it has no start-up transient.
    output_ = has_output_ ? lowpass_pole_ * output_ + (Scalar(1) - lowpass_pole_) * raw : raw;
    has_output_ = true;
    previous1_ = t1;
    previous2_ = t2;
    *gas = output_;
    return Status::ok;
  }

 private:
  Config config_{};
  FirstOrderSensor<Scalar> sensor1_{};
  FirstOrderSensor<Scalar> sensor2_{};
  Scalar weight1_{1};
  Scalar lowpass_pole_{0};
  Scalar previous1_{0};
  Scalar previous2_{0};
  Scalar output_{0};
  bool has_previous_{false};
  bool has_output_{false};
};

}  // namespace dualprobe
