// The C API of dualprobe.h over the C++ core templates, float only. Each C instance is raw
// storage holding one core object built there with placement new: no heap, no static
// initialisers, no exceptions (every core call is noexcept).
#include "dualprobe/dualprobe.h"

#include <cmath>
#include <cstring>
#include <limits>
#include <new>
#include <type_traits>

#include "dualprobe/difference_estimator.hpp"
#include "dualprobe/first_order.hpp"
#include "dualprobe/reconstruct.hpp"
#include "dualprobe/status.hpp"

namespace {

using Estimator = dualprobe::DifferenceEstimator<float>;

// Streaming exact-inverse reconstruction. Same arithmetic as dualprobe::InverseReconstructor
// (FirstOrderSensor::inverse, sensor1_weight, first-order low-pass started from its first
// input), but retuning the time constants keeps the previous sample and the low-pass state, so
// the firmware can retune after every solve without a gap or a low-pass restart.
struct Reconstructor {
  dualprobe::FirstOrderSensor<float> sensor1{};
  dualprobe::FirstOrderSensor<float> sensor2{};
  float sample_interval{1.0f};
  float weight1{1.0f};
  float lowpass_pole{0.0f};
  float previous1{0.0f};
  float previous2{0.0f};
  float output{0.0f};
  dp_source source{DP_SOURCE_WEIGHTED};
  bool configured{false};
  bool has_previous{false};
  bool has_output{false};

  bool set_time_constants(float tau1, float tau2) noexcept {
    dualprobe::FirstOrderSensor<float> s1;
    dualprobe::FirstOrderSensor<float> s2;
    if (!s1.set_time_constant(tau1, sample_interval) ||
        !s2.set_time_constant(tau2, sample_interval)) {
      return false;
    }
    sensor1 = s1;
    sensor2 = s2;
    switch (source) {
      case DP_SOURCE_SENSOR1: weight1 = 1.0f; break;
      case DP_SOURCE_SENSOR2: weight1 = 0.0f; break;
      case DP_SOURCE_WEIGHTED: weight1 = dualprobe::sensor1_weight(tau1, tau2); break;
    }
    return true;
  }

  dp_status update(float t1, float t2, float* gas) noexcept {
    if (!configured) return DP_STATUS_INVALID_ARGUMENT;
    if (!std::isfinite(t1) || !std::isfinite(t2)) return DP_STATUS_NON_FINITE_INPUT;
    if (!has_previous) {
      previous1 = t1;
      previous2 = t2;
      has_previous = true;
      return DP_STATUS_NOT_READY;
    }
    const float g1 = sensor1.inverse(t1, previous1);
    const float g2 = sensor2.inverse(t2, previous2);
    const float raw = weight1 * g1 + (1.0f - weight1) * g2;
    const float next = has_output ? lowpass_pole * output + (1.0f - lowpass_pole) * raw : raw;
    previous1 = t1;
    previous2 = t2;
    // Huge samples or a near-zero b can overflow float: never report such a value as ok, and
    // keep the low-pass state finite.
    if (!std::isfinite(next)) return DP_STATUS_INFEASIBLE;
    output = next;
    has_output = true;
    *gas = output;
    return DP_STATUS_OK;
  }
};

static_assert(sizeof(Estimator) <= sizeof(dp_diff_instance_f32::storage),
              "DP_DIFF_INSTANCE_BYTES too small for DifferenceEstimator<float>");
static_assert(alignof(Estimator) <= alignof(dp_diff_instance_f32),
              "dp_diff_instance_f32 under-aligned for DifferenceEstimator<float>");
static_assert(sizeof(Reconstructor) <= sizeof(dp_recon_instance_f32::storage),
              "DP_RECON_INSTANCE_BYTES too small");
static_assert(alignof(Reconstructor) <= alignof(dp_recon_instance_f32),
              "dp_recon_instance_f32 under-aligned");
// The ECU budget of issue 4, on what the firmware actually allocates.
static_assert(sizeof(dp_diff_instance_f32) <= 128, "estimator instance exceeds 128 bytes");
// Placement new into storage that the C side may copy or zero: both must be trivial.
static_assert(std::is_trivially_destructible<Estimator>::value, "estimator needs a destructor");
static_assert(std::is_trivially_destructible<Reconstructor>::value, "reconstructor needs one");

static_assert(static_cast<int>(dualprobe::Status::ok) == DP_STATUS_OK, "status mismatch");
static_assert(static_cast<int>(dualprobe::Status::insufficient_excitation) ==
                  DP_STATUS_INSUFFICIENT_EXCITATION,
              "status mismatch");
static_assert(static_cast<int>(dualprobe::Status::infeasible) == DP_STATUS_INFEASIBLE,
              "status mismatch");
static_assert(static_cast<int>(dualprobe::Status::non_finite_input) == DP_STATUS_NON_FINITE_INPUT,
              "status mismatch");
static_assert(static_cast<int>(dualprobe::Status::invalid_argument) == DP_STATUS_INVALID_ARGUMENT,
              "status mismatch");
static_assert(static_cast<int>(dualprobe::Status::not_ready) == DP_STATUS_NOT_READY,
              "status mismatch");
static_assert(static_cast<int>(dualprobe::Method::ls) == DP_METHOD_LS, "method mismatch");
static_assert(static_cast<int>(dualprobe::Method::tls) == DP_METHOD_TLS, "method mismatch");
static_assert(static_cast<int>(dualprobe::Method::gtls) == DP_METHOD_GTLS, "method mismatch");

Estimator* estimator(dp_diff_instance_f32* instance) noexcept {
  return std::launder(reinterpret_cast<Estimator*>(instance->storage.words));
}
const Estimator* estimator(const dp_diff_instance_f32* instance) noexcept {
  return std::launder(reinterpret_cast<const Estimator*>(instance->storage.words));
}
Reconstructor* reconstructor(dp_recon_instance_f32* instance) noexcept {
  return std::launder(reinterpret_cast<Reconstructor*>(instance->storage.words));
}

dp_status to_c(dualprobe::Status status) noexcept { return static_cast<dp_status>(status); }

// A C caller may store any integer in an enum field; reading it through the C++ enum type
// would be undefined for values outside the enumerators' range, so read its representation
// (int-sized on most ABIs, one byte with arm-none-eabi's default -fshort-enums).
template <typename Enum>
int enum_value(const Enum* field) noexcept {
  std::underlying_type_t<Enum> value;
  static_assert(sizeof value == sizeof(Enum), "enum representation");
  std::memcpy(&value, field, sizeof value);
  return static_cast<int>(value);
}

}  // namespace

extern "C" {

dp_status dp_diff_init_f32(dp_diff_instance_f32* instance, const dp_diff_config_f32* config) {
  if (instance == nullptr) return DP_STATUS_INVALID_ARGUMENT;
  std::memset(instance, 0, sizeof(*instance));
  // An unconfigured estimator (default config: GTLS with zero noise) refuses to solve with
  // invalid_argument, which is the documented state after a failed init.
  Estimator* est = new (instance->storage.words) Estimator();
  if (config == nullptr) return DP_STATUS_INVALID_ARGUMENT;
  const int method = enum_value(&config->method);
  if (method < DP_METHOD_LS || method > DP_METHOD_GTLS) return DP_STATUS_INVALID_ARGUMENT;
  Estimator::Config core_config;
  core_config.sample_interval = config->sample_interval;
  core_config.method = static_cast<dualprobe::Method>(method);
  core_config.sigma1 = config->sigma1;
  core_config.sigma2 = config->sigma2;
  core_config.forgetting = config->forgetting;
  return to_c(est->configure(core_config));
}

void dp_diff_reset_f32(dp_diff_instance_f32* instance) {
  if (instance != nullptr) estimator(instance)->reset();
}

void dp_diff_break_chain_f32(dp_diff_instance_f32* instance) {
  if (instance != nullptr) estimator(instance)->break_chain();
}

dp_status dp_diff_update_f32(dp_diff_instance_f32* instance, float t1, float t2) {
  if (instance == nullptr) return DP_STATUS_INVALID_ARGUMENT;
  Estimator* est = estimator(instance);
  // The refusal (DifferenceEstimator::update's: break the chain, non_finite_input) spelled out
  // here: left inside update(), it makes GCC copy the instance pointer on every call, one
  // instruction over the M4F's 60-instruction budget for the finite path.
  if (std::isfinite(t1) && std::isfinite(t2)) return to_c(est->update(t1, t2));
  est->break_chain();
  return DP_STATUS_NON_FINITE_INPUT;
}

dp_status dp_diff_update_block_f32(dp_diff_instance_f32* instance, const float* t1,
                                   const float* t2, uint32_t block_size) {
  if (instance == nullptr || (block_size > 0 && (t1 == nullptr || t2 == nullptr))) {
    return DP_STATUS_INVALID_ARGUMENT;
  }
  Estimator* est = estimator(instance);
  dp_status first = DP_STATUS_OK;
  for (uint32_t k = 0; k < block_size; ++k) {
    const dp_status status = to_c(est->update(t1[k], t2[k]));
    if (first == DP_STATUS_OK) first = status;
  }
  return first;
}

dp_status dp_diff_solve_f32(const dp_diff_instance_f32* instance, dp_diff_result_f32* result) {
  if (instance == nullptr || result == nullptr) return DP_STATUS_INVALID_ARGUMENT;
  const Estimator* est = estimator(instance);
  dp_diff_result_f32 out{};
  if (!est->config().valid()) {
    out.status = DP_STATUS_INVALID_ARGUMENT;
  } else {
    const Estimator::Result solved = est->solve();
    out.status = to_c(solved.status);
    out.beta = solved.beta;
    out.b1 = solved.b1;
    out.b2 = solved.b2;
    out.tau1 = solved.tau1;
    out.tau2 = solved.tau2;
    out.eigenvalue_ratio = solved.eigenvalue_ratio;
    // The contract of an ok status: every number finite and physical. Float rounding at the
    // edge of the feasible set (b = 1 - 1 ulp gives tau = Ts / ln(2^24)...) must not pass a
    // non-finite or non-positive time constant to the caller.
    if (out.status == DP_STATUS_OK &&
        !(std::isfinite(out.tau1) && std::isfinite(out.tau2) && out.tau1 > 0.0f &&
          out.tau2 > 0.0f && std::isfinite(out.eigenvalue_ratio))) {
      out.status = DP_STATUS_INFEASIBLE;
    }
  }
  *result = out;
  return out.status;
}

float dp_diff_rows_f32(const dp_diff_instance_f32* instance) {
  if (instance == nullptr) return 0.0f;
  return estimator(instance)->rows();
}

dp_status dp_diff_scatter_f32(const dp_diff_instance_f32* instance, float packed[6]) {
  if (instance == nullptr || packed == nullptr) return DP_STATUS_INVALID_ARGUMENT;
  const Eigen::Matrix<float, 3, 3> s = estimator(instance)->scatter();
  int index = 0;
  for (int row = 0; row < 3; ++row) {
    for (int col = row; col < 3; ++col) packed[index++] = s(row, col);
  }
  return DP_STATUS_OK;
}

dp_status dp_recon_init_f32(dp_recon_instance_f32* instance, const dp_recon_config_f32* config) {
  if (instance == nullptr) return DP_STATUS_INVALID_ARGUMENT;
  std::memset(instance, 0, sizeof(*instance));
  Reconstructor* rec = new (instance->storage.words) Reconstructor();
  if (config == nullptr) return DP_STATUS_INVALID_ARGUMENT;
  const int source = enum_value(&config->source);
  const bool lowpass_ok = config->lowpass_tau >= 0.0f && std::isfinite(config->lowpass_tau);
  if (source < DP_SOURCE_SENSOR1 || source > DP_SOURCE_WEIGHTED || !lowpass_ok) {
    return DP_STATUS_INVALID_ARGUMENT;
  }
  rec->sample_interval = config->sample_interval;
  rec->source = static_cast<dp_source>(source);
  if (!rec->set_time_constants(config->tau1, config->tau2)) return DP_STATUS_INVALID_ARGUMENT;
  rec->lowpass_pole =
      config->lowpass_tau > 0.0f ? std::exp(-config->sample_interval / config->lowpass_tau) : 0.0f;
  rec->configured = true;
  return DP_STATUS_OK;
}

void dp_recon_reset_f32(dp_recon_instance_f32* instance) {
  if (instance == nullptr) return;
  Reconstructor* rec = reconstructor(instance);
  rec->has_previous = false;
  rec->has_output = false;
}

dp_status dp_recon_set_time_constants_f32(dp_recon_instance_f32* instance, float tau1,
                                          float tau2) {
  if (instance == nullptr) return DP_STATUS_INVALID_ARGUMENT;
  Reconstructor* rec = reconstructor(instance);
  if (!rec->configured || !rec->set_time_constants(tau1, tau2)) return DP_STATUS_INVALID_ARGUMENT;
  return DP_STATUS_OK;
}

dp_status dp_recon_update_f32(dp_recon_instance_f32* instance, float t1, float t2, float* gas) {
  if (instance == nullptr || gas == nullptr) return DP_STATUS_INVALID_ARGUMENT;
  return reconstructor(instance)->update(t1, t2, gas);
}

dp_status dp_recon_block_f32(dp_recon_instance_f32* instance, const float* t1, const float* t2,
                             float* gas, uint32_t block_size) {
  if (instance == nullptr ||
      (block_size > 0 && (t1 == nullptr || t2 == nullptr || gas == nullptr))) {
    return DP_STATUS_INVALID_ARGUMENT;
  }
  Reconstructor* rec = reconstructor(instance);
  dp_status first = DP_STATUS_OK;
  for (uint32_t k = 0; k < block_size; ++k) {
    gas[k] = std::numeric_limits<float>::quiet_NaN();
    const dp_status status = rec->update(t1[k], t2[k], &gas[k]);
    if (first == DP_STATUS_OK && status != DP_STATUS_OK && status != DP_STATUS_NOT_READY) {
      first = status;
    }
  }
  return first;
}

const char* dp_status_string(dp_status status) {
  const int value = enum_value(&status);
  if (value < DP_STATUS_OK || value > DP_STATUS_NOT_READY) return "unknown";
  return dualprobe::to_string(static_cast<dualprobe::Status>(value));
}

}  // extern "C"
