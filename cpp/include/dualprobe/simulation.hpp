// Hot simulation loops that are nonlinear recursions (no lfilter equivalent), used by the
// Python workflows on long records.
#pragma once

#include <cmath>
#include <cstddef>

#include "dualprobe/first_order.hpp"
#include "dualprobe/status.hpp"

namespace dualprobe {

// First-order sensor whose time constant depends on the direction of heat flow, with the gas
// held over each sample interval (ZOH):
//   T(k) = T(k-1) + b_dir (Tg(k-1) - T(k-1)),  b_dir from tau_heat if Tg(k-1) > T(k-1), else tau_cool.
// out[0] = initial; out must hold n values.
template <typename Scalar>
Status simulate_hysteretic_first_order(const Scalar* gas, std::size_t n, Scalar ts, Scalar tau_heat,
                                       Scalar tau_cool, Scalar initial, Scalar* out) noexcept {
  FirstOrderSensor<Scalar> heat;
  FirstOrderSensor<Scalar> cool;
  if (!heat.set_time_constant(tau_heat, ts) || !cool.set_time_constant(tau_cool, ts) ||
      !std::isfinite(initial)) {
    return Status::invalid_argument;
  }
  if (n == 0) return Status::ok;
  Scalar state = initial;
  out[0] = state;
  for (std::size_t k = 1; k < n; ++k) {
    const Scalar drive = gas[k - 1] - state;
    state += (drive > Scalar(0) ? heat.b : cool.b) * drive;
    out[k] = state;
  }
  return Status::ok;
}

}  // namespace dualprobe
