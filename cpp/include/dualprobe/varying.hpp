// First-order recursion with a coefficient pair per sample interval, switched by the direction
// of heat flow: a sensor whose time constant varies along the record (it follows the gas
// velocity or the temperature level) and may differ between heating and cooling. The caller
// computes the coefficients of the exact discretisation it wants (first- or zero-order hold of
// the input), so the loop is the only part that cannot be vectorised.
#pragma once

#include <cmath>
#include <cstddef>

#include "dualprobe/status.hpp"

namespace dualprobe {

// out[0] = initial and, for k = 0 .. n-2,
//   out[k+1] = a_heat[k] out[k] + f_heat[k]   if drive[k] > out[k] (heat flows into the sensor)
//            = a_cool[k] out[k] + f_cool[k]   otherwise.
// drive, a_*, f_* hold n - 1 values (interval k runs from sample k to k + 1); out holds n.
// With a = exp(-Ts/tau_k) and f = (1 - a) Tg(k) this is simulate_hysteretic_first_order with a
// time constant per interval. Passing the same arrays for heating and cooling gives the linear
// time-varying recursion. No allocation; invalid_argument for a non-finite initial value.
template <typename Scalar>
Status simulate_switched_first_order(const Scalar* drive, const Scalar* a_heat,
                                     const Scalar* f_heat, const Scalar* a_cool,
                                     const Scalar* f_cool, std::size_t n, Scalar initial,
                                     Scalar* out) noexcept {
  if (!std::isfinite(initial)) return Status::invalid_argument;
  if (n == 0) return Status::ok;
  Scalar state = initial;
  out[0] = state;
  for (std::size_t k = 0; k + 1 < n; ++k) {
    state = drive[k] > state ? a_heat[k] * state + f_heat[k] : a_cool[k] * state + f_cool[k];
    out[k + 1] = state;
  }
  return Status::ok;
}

}  // namespace dualprobe
