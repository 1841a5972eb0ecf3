// Discrete first-order sensor model of the paper's eqs. (8)-(9):
//   T(k) = a T(k-1) + b Tg(k-1),  a = exp(-Ts/tau),  b = 1 - a.
#pragma once

#include <cmath>

namespace dualprobe {

template <typename Scalar>
struct FirstOrderSensor {
  Scalar a{0};
  Scalar b{1};

  // Returns false (and leaves the model untouched) unless tau > 0 and Ts > 0 are finite.
  bool set_time_constant(Scalar tau, Scalar ts) noexcept {
    if (!(tau > Scalar(0)) || !(ts > Scalar(0)) || !std::isfinite(tau) || !std::isfinite(ts)) {
      return false;
    }
    // expm1 keeps b accurate when Ts << tau, where 1 - exp(-Ts/tau) would cancel.
    b = -std::expm1(-ts / tau);
    a = Scalar(1) - b;
    return true;
  }

  static Scalar time_constant_from_b(Scalar b_value, Scalar ts) noexcept {
    // tau = -Ts / ln(1 - b); log1p for the same reason as expm1 above.
    return -ts / std::log1p(-b_value);
  }

  Scalar step(Scalar previous_output, Scalar previous_gas) const noexcept {
    return a * previous_output + b * previous_gas;
  }

  // Exact inverse of step(): the gas temperature over [k-1, k) from T(k-1) and T(k).
  Scalar inverse(Scalar output, Scalar previous_output) const noexcept {
    return (output - a * previous_output) / b;
  }
};

}  // namespace dualprobe
