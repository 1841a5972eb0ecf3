// The Kalman half of the noise-robust C API (dualprobe.h, issue 13): the causal
// reconstruction of kalman.hpp with per-sample time constants tau_ref / psi(k), the interval's
// model formed in float in closed form (no matrix exponential per tick). Each C instance is
// raw storage holding one core object built with placement new: no heap.
#include <cmath>
#include <cstdint>
#include <cstring>
#include <new>
#include <type_traits>

#include "dualprobe/dualprobe.h"
#include "dualprobe/kalman.hpp"
#include "dualprobe/status.hpp"
#include "robust_detail.hpp"

namespace {

using namespace dualprobe::c_detail;

// ---- Kalman ------------------------------------------------------------------------------

constexpr int kWindow = DP_KALMAN_MAX_WINDOW;
constexpr int kLag = DP_KALMAN_MAX_LAG;
template <int N>
using Kalman = dualprobe::KalmanReconstructor<float, N, 1, kWindow>;
// The fixed-lag output runs on a second, jump-free filter (kalman.hpp: a GLR jump's effect on
// the lagged instants is not tracked): same model, same samples, no GLR window (~30 % of the
// causal filter's bytes, most of them the lag ring).
template <int N>
using Lagged = dualprobe::KalmanReconstructor<float, N, 1, 1, kLag>;

struct RobustKalman {
  alignas(max_align<Kalman<3>, Kalman<5>>()) unsigned char core[max_size<Kalman<3>, Kalman<5>>()];
  alignas(max_align<Lagged<3>, Lagged<5>>()) unsigned char lagged[max_size<Lagged<3>, Lagged<5>>()];
  int lag{0};  // 0: no fixed-lag filter
  float ts{1};
  float taus[2][2]{};
  float variance[2]{};
  float intensity{0};
  int order[2]{1, 1};
  int states{0};  // 3 (Kalman<3>) or 5 (Kalman<5>, 4 or 5 used); 0: not configured

  template <int N>
  Kalman<N>* as() noexcept { return placed<Kalman<N>>(core); }
  template <int N>
  const Kalman<N>* as() const noexcept { return placed<Kalman<N>>(core); }
  template <int N>
  Lagged<N>* lag_filter() noexcept { return placed<Lagged<N>>(lagged); }
  template <int N>
  const Lagged<N>* lag_filter() const noexcept { return placed<Lagged<N>>(lagged); }
};

static_assert(sizeof(RobustKalman) <= sizeof(dp_kalman_instance_f32::storage),
              "DP_KALMAN_INSTANCE_BYTES too small");
static_assert(alignof(RobustKalman) <= alignof(dp_kalman_instance_f32), "alignment");
static_assert(std::is_trivially_destructible<Kalman<5>>::value, "Kalman needs a destructor");
// Issue 13's budget on what the firmware allocates: estimator + reconstructor <= 4 KiB.
static_assert(sizeof(dp_svf_instance_f32) + sizeof(dp_kalman_instance_f32) <= 4096,
              "robust estimator + reconstructor exceed 4 KiB");

RobustKalman* kalman(dp_kalman_instance_f32* instance) noexcept {
  return std::launder(reinterpret_cast<RobustKalman*>(instance->storage.words));
}
const RobustKalman* kalman(const dp_kalman_instance_f32* instance) noexcept {
  return std::launder(reinterpret_cast<const RobustKalman*>(instance->storage.words));
}

// expm1(x) / x without cancellation near 0.
float relative_expm1(float x) noexcept {
  if (std::fabs(x) < 1e-4f) return 1.0f + 0.5f * x;
  return det_expm1(x) / x;
}

// Phi and q Ts w w^T + floors of one interval with the time constants tau_ref / psi: per stage
// exact (gas held over the interval, as the random walk's mean is), the process noise by the
// midpoint rule (w: Phi(Ts/2) e_0, so the gas variance q Ts is exact) plus the core's floors.
template <int N>
void interval_model(const RobustKalman& k, float psi, Eigen::Matrix<float, N, N>& phi,
                    Eigen::Matrix<float, N, N>& process) noexcept {
  phi.setIdentity();
  process.setZero();
  const float h = k.ts;
  float w[N] = {};
  w[0] = 1.0f;
  float tau_now[4] = {1, 1, 1, 1};
  int index = 1;
  for (int sensor = 0; sensor < 2; ++sensor) {
    const float a = k.taus[sensor][0] / psi;
    const float em = det_expm1(-h / a);  // ea - 1
    const float ea = 1.0f + em;
    const float ea_half = std::sqrt(ea);
    phi(index, index) = ea;
    phi(index, 0) = -em;
    w[index] = -em / (1.0f + ea_half);  // 1 - e^(-h/2a)
    tau_now[index - 1] = a;
    if (k.order[sensor] == 2) {
      const float b = k.taus[sensor][1] / psi;
      const float emb = det_expm1(-h / b);
      const float eb = 1.0f + emb;
      const float hd = h * (1.0f / b - 1.0f / a);
      const float rel = relative_expm1(hd);
      const float m21 = (h / b) * eb * rel;  // the first stage's start state -> second stage
      phi(index + 1, index + 1) = eb;
      phi(index + 1, index) = m21;
      phi(index + 1, 0) = -emb - m21;  // rows sum to one: unit static gain
      // The same at h / 2: e^(-h/2b) = sqrt(eb), expm1(x/2) = expm1(x) / (sqrt(1 + expm1 x) + 1).
      const float eb_half = std::sqrt(eb);
      const float rel_half = 2.0f * rel / (std::sqrt(1.0f + hd * rel) + 1.0f);
      const float m21_half = (0.5f * h / b) * eb_half * rel_half;
      w[index + 1] = 1.0f - eb_half - m21_half;
      tau_now[index] = b;
    }
    index += k.order[sensor];
  }
  const float gas_step = k.intensity * h;
  for (int i = 0; i < index; ++i) {
    for (int j = 0; j <= i; ++j) {
      const float v = gas_step * w[i] * w[j];
      process(i, j) = v;
      process(j, i) = v;
    }
  }
  int stage = 0;
  for (int sensor = 0; sensor < 2; ++sensor) {
    for (int s = 0; s < k.order[sensor]; ++s, ++stage) {
      const float ratio = h / tau_now[stage];
      process(stage + 1, stage + 1) +=
          float(dualprobe::kalman_detail::kFloorRel) * k.variance[sensor] +
          float(dualprobe::kalman_detail::kFloorDyn) * gas_step * ratio * ratio / 12.0f;
    }
  }
}

template <int N>
dp_status kalman_update(RobustKalman* k, float t1, float t2, float psi, float* gas) noexcept {
  Eigen::Matrix<float, N, N> phi;
  Eigen::Matrix<float, N, N> process;
  interval_model<N>(*k, psi, phi, process);
  Kalman<N>* core = k->as<N>();
  if (core->set_model(phi, process) != dualprobe::Status::ok) return DP_STATUS_INFEASIBLE;
  float out = 0.0f;
  const dualprobe::Status status = core->update(t1, t2, &out);
  if (k->lag > 0) {
    // Every valid sample, whatever the causal filter's status, so both stay on one time grid;
    // a failed lagged update restarts that filter only (not ready for lag samples).
    Lagged<N>* lagged = k->lag_filter<N>();
    if (lagged->set_model(phi, process) == dualprobe::Status::ok) (void)lagged->update(t1, t2);
  }
  if (status != dualprobe::Status::ok) return static_cast<dp_status>(status);
  *gas = out;
  return DP_STATUS_OK;
}

bool valid_taus(const float taus[2], int order) noexcept {
  return finite_positive(taus[0]) && (order == 1 || finite_positive(taus[1]));
}

}  // namespace

extern "C" {

dp_status dp_kalman_init_f32(dp_kalman_instance_f32* instance, const dp_kalman_config_f32* config) {
  if (instance == nullptr) return DP_STATUS_INVALID_ARGUMENT;
  std::memset(instance, 0, sizeof(*instance));
  RobustKalman* k = new (instance->storage.words) RobustKalman();
  if (config == nullptr) return DP_STATUS_INVALID_ARGUMENT;
  const uint32_t o1 = config->order1;
  const uint32_t o2 = config->order2;
  if (o1 < 1u || o1 > 2u || o2 < 1u || o2 > 2u) return DP_STATUS_INVALID_ARGUMENT;
  if (!valid_taus(config->taus1, int(o1)) || !valid_taus(config->taus2, int(o2))) {
    return DP_STATUS_INVALID_ARGUMENT;
  }
  const float floor = config->quantisation * config->quantisation / 12.0f;
  if (!(config->quantisation >= 0.0f) || !std::isfinite(config->quantisation) ||
      !(config->sigma1 >= 0.0f) || !(config->sigma2 >= 0.0f) ||
      !finite_positive(config->intensity) || config->window > uint32_t(kWindow) ||
      config->lag > uint32_t(kLag)) {
    return DP_STATUS_INVALID_ARGUMENT;
  }
  dualprobe::KalmanConfig<float> core;
  core.sample_interval = config->sample_interval;
  core.order1 = int(o1);
  core.order2 = int(o2);
  core.taus1 = {{config->taus1[0], o1 == 2u ? config->taus1[1] : 1.0f}};
  core.taus2 = {{config->taus2[0], o2 == 2u ? config->taus2[1] : 1.0f}};
  core.sigma1 = std::sqrt(config->sigma1 * config->sigma1 + floor);
  core.sigma2 = std::sqrt(config->sigma2 * config->sigma2 + floor);
  core.intensity = config->intensity;
  core.detect_jumps = config->window > 0u;
  core.window = config->window > 0u ? int(config->window) : 1;
  core.false_alarm = config->false_alarm;
  const int states = o1 + o2 == 2u ? 3 : 5;
  const dualprobe::Status status = states == 3 ? (new (k->core) Kalman<3>())->configure(core)
                                               : (new (k->core) Kalman<5>())->configure(core);
  if (status != dualprobe::Status::ok) return DP_STATUS_INVALID_ARGUMENT;
  if (config->lag > 0u) {
    core.detect_jumps = false;
    core.window = 1;
    core.lag = int(config->lag);
    const dualprobe::Status lagged = states == 3
                                         ? (new (k->lagged) Lagged<3>())->configure(core)
                                         : (new (k->lagged) Lagged<5>())->configure(core);
    if (lagged != dualprobe::Status::ok) return DP_STATUS_INVALID_ARGUMENT;
  }
  k->ts = config->sample_interval;
  for (int j = 0; j < 2; ++j) {
    k->taus[0][j] = core.taus1[j];
    k->taus[1][j] = core.taus2[j];
  }
  k->variance[0] = core.sigma1 * core.sigma1;
  k->variance[1] = core.sigma2 * core.sigma2;
  k->intensity = config->intensity;
  k->order[0] = int(o1);
  k->order[1] = int(o2);
  k->lag = int(config->lag);
  k->states = states;
  return DP_STATUS_OK;
}

void dp_kalman_reset_f32(dp_kalman_instance_f32* instance) {
  if (instance == nullptr) return;
  RobustKalman* k = kalman(instance);
  if (k->states == 3) k->as<3>()->reset();
  if (k->states == 5) k->as<5>()->reset();
  if (k->lag > 0 && k->states == 3) k->lag_filter<3>()->reset();
  if (k->lag > 0 && k->states == 5) k->lag_filter<5>()->reset();
}

dp_status dp_kalman_retune_f32(dp_kalman_instance_f32* instance, const float taus1[2],
                               const float taus2[2]) {
  if (instance == nullptr || taus1 == nullptr || taus2 == nullptr) {
    return DP_STATUS_INVALID_ARGUMENT;
  }
  RobustKalman* k = kalman(instance);
  if (k->states == 0 || !valid_taus(taus1, k->order[0]) || !valid_taus(taus2, k->order[1])) {
    return DP_STATUS_INVALID_ARGUMENT;
  }
  for (int j = 0; j < k->order[0]; ++j) k->taus[0][j] = taus1[j];
  for (int j = 0; j < k->order[1]; ++j) k->taus[1][j] = taus2[j];
  return DP_STATUS_OK;
}

dp_status dp_kalman_update_f32(dp_kalman_instance_f32* instance, float t1, float t2, float psi,
                               float* gas) {
  if (instance == nullptr || gas == nullptr) return DP_STATUS_INVALID_ARGUMENT;
  RobustKalman* k = kalman(instance);
  if (k->states == 0) return DP_STATUS_INVALID_ARGUMENT;
  if (!std::isfinite(t1) || !std::isfinite(t2) || !std::isfinite(psi)) {
    return DP_STATUS_NON_FINITE_INPUT;
  }
  if (!(psi > 0.0f)) return DP_STATUS_INVALID_ARGUMENT;
  return k->states == 3 ? kalman_update<3>(k, t1, t2, psi, gas)
                        : kalman_update<5>(k, t1, t2, psi, gas);
}

uint32_t dp_kalman_jumps_f32(const dp_kalman_instance_f32* instance) {
  if (instance == nullptr) return 0u;
  const RobustKalman* k = kalman(instance);
  if (k->states == 3) return k->as<3>()->jump_count();
  if (k->states == 5) return k->as<5>()->jump_count();
  return 0u;
}

dp_status dp_kalman_lagged_f32(const dp_kalman_instance_f32* instance, float* gas, float* std) {
  if (instance == nullptr) return DP_STATUS_INVALID_ARGUMENT;
  const RobustKalman* k = kalman(instance);
  float mean = 0.0f;
  float variance = 0.0f;
  bool ready = false;
  if (k->lag > 0 && k->states == 3) ready = k->lag_filter<3>()->lagged(&mean, &variance);
  if (k->lag > 0 && k->states == 5) ready = k->lag_filter<5>()->lagged(&mean, &variance);
  if (!ready) return DP_STATUS_NOT_READY;
  if (gas != nullptr) *gas = mean;
  if (std != nullptr) *std = std::sqrt(variance);
  return DP_STATUS_OK;
}

}  // extern "C"
