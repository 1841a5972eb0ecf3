// Status codes shared by every estimator of the core. Plain enum values so the C API can mirror
// them one for one.
#pragma once

namespace dualprobe {

enum class Status : int {
  ok = 0,
  insufficient_excitation = 1,  // too few samples, or the signals do not move enough to solve
  infeasible = 2,               // a solution exists but is not physical (b outside (0,1), beta <= 0)
  non_finite_input = 3,         // NaN or Inf sample refused (a difference chain is broken)
  invalid_argument = 4,         // configuration out of range; state untouched
  not_ready = 5,                // the estimator has no solution yet
};

constexpr const char* to_string(Status status) noexcept {
  switch (status) {
    case Status::ok: return "ok";
    case Status::insufficient_excitation: return "insufficient_excitation";
    case Status::infeasible: return "infeasible";
    case Status::non_finite_input: return "non_finite_input";
    case Status::invalid_argument: return "invalid_argument";
    case Status::not_ready: return "not_ready";
  }
  return "unknown";
}

}  // namespace dualprobe
