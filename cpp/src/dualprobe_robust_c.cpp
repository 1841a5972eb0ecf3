// The noise-robust half of the C API (dualprobe.h, issue 13): the SVF cross-relation estimator
// with an optional flow schedule, and the causal Kalman reconstruction scheduled per sample.
// Float only, solve included (SolveScalar = float): no double arithmetic per sample or per
// solve, so nothing runs in soft-float on a Cortex-M4F. Each C instance is raw storage
// holding one core object built with placement new: no heap, no static initialisers.
#include <cmath>
#include <cstdint>
#include <cstring>
#include <new>
#include <type_traits>

#include "dualprobe/dualprobe.h"
#include "dualprobe/kalman.hpp"
#include "dualprobe/status.hpp"
#include "dualprobe/svf_estimator.hpp"

namespace {

// ---- deterministic float exp / expm1 / log ------------------------------------------------
// libm's expf/expm1f/logf differ in the last bit between glibc and newlib; on the per-sample
// path (the flow schedule, the Kalman's per-interval model) one ulp grows into a different
// solve status and so a different run. These use only + - * / and IEEE sqrt-free bit
// manipulation, so host and M4F round identically (with -ffp-contract=off); accuracy 2-3 ulp,
// far below everything they feed (time constants known to 1e-3 at best).
float bits_to_float(std::uint32_t bits) noexcept {
  float value;
  std::memcpy(&value, &bits, sizeof value);
  return value;
}

// e^r - 1 for |r| <= ln2/2 (Taylor to degree 8: truncation r^9/9! < 2e-11), no cancellation.
float expm1_reduced(float r) noexcept {
  float p = 1.0f / 40320.0f;
  p = p * r + 1.0f / 5040.0f;
  p = p * r + 1.0f / 720.0f;
  p = p * r + 1.0f / 120.0f;
  p = p * r + 1.0f / 24.0f;
  p = p * r + 1.0f / 6.0f;
  p = p * r + 0.5f;
  return r + r * r * p;
}

// x = n ln2 + r, |r| <= ln2/2 (Cody-Waite split of ln2).
float reduce(float x, int* n) noexcept {
  const float k = x * 1.44269504f;
  *n = int(k + (k >= 0.0f ? 0.5f : -0.5f));
  const float fn = float(*n);
  return (x - fn * 0.693145751953125f) - fn * 1.428606820309417232e-6f;
}

float det_exp(float x) noexcept {
  if (!(x < 88.0f)) return x != x ? x : bits_to_float(0x7F800000u);  // NaN, +inf
  if (x < -87.0f) return 0.0f;
  int n = 0;
  const float r = reduce(x, &n);
  return (1.0f + expm1_reduced(r)) * bits_to_float(std::uint32_t(n + 127) << 23);
}

float det_expm1(float x) noexcept {
  if (x > -0.34657359f && x < 0.34657359f) return expm1_reduced(x);
  return det_exp(x) - 1.0f;
}

// log(x) for finite x > 0: x = m 2^e with m in [sqrt(1/2), sqrt(2)), log m = 2 atanh(s),
// s = (m - 1)/(m + 1), |s| <= 0.1716: series to s^11 (truncation < 1e-10).
float det_log(float x) noexcept {
  if (!(x > 0.0f) || x != x) return bits_to_float(0x7FC00000u);
  std::uint32_t bits;
  std::memcpy(&bits, &x, sizeof bits);
  if (bits >= 0x7F800000u) return x;  // +inf
  if (bits < 0x00800000u) return -87.3365448f;  // denormals: clamp (never on this path)
  int e = int(bits >> 23) - 127;
  float m = bits_to_float((bits & 0x007FFFFFu) | 0x3F800000u);
  if (m > 1.41421356f) {
    m *= 0.5f;
    ++e;
  }
  const float s = (m - 1.0f) / (m + 1.0f);
  const float s2 = s * s;
  float p = 1.0f / 11.0f;
  p = p * s2 + 1.0f / 9.0f;
  p = p * s2 + 1.0f / 7.0f;
  p = p * s2 + 1.0f / 5.0f;
  p = p * s2 + 1.0f / 3.0f;
  const float log_m = 2.0f * s + 2.0f * s * s2 * p;
  const float fe = float(e);
  return (fe * 1.428606820309417232e-6f + log_m) + fe * 0.693145751953125f;
}

// r^m_j of the basis: square roots only (IEEE sqrt is correctly rounded everywhere).
void basis_weights(float ratio, float out[3]) noexcept {
  const float root2 = std::sqrt(ratio);
  const float root4 = std::sqrt(root2);
  out[0] = root4;
  out[1] = root2;
  out[2] = root2 * root4;
}

// ---- SVF ---------------------------------------------------------------------------------

// The flow basis: b_j = r^m_j with m_j = 0.25, 0.5, 0.75 (r = flow / flow_ref), two square
// roots and a product per sample. psi = sum_j a_j b_j interpolates r^m for m in ~[0.1, 0.9]
// (max relative error of the best combination over r in [0.3, 3]: below 1e-3 for m in
// [0.2, 0.8], see tests/cpp/c_api/test_robust_c_api.cpp).
constexpr int kBasis = 3;
constexpr int kExponentGrid = 9;  // points of the log-log fit of m

template <int Order, int Basis>
using Svf = dualprobe::SvfEstimator<float, Order, dualprobe::StaticModel::unit, false, 1, float,
                                    Basis>;

template <typename... T>
constexpr std::size_t max_size() {
  std::size_t out = 0;
  for (std::size_t s : {sizeof(T)...}) out = s > out ? s : out;
  return out;
}
template <typename... T>
constexpr std::size_t max_align() {
  std::size_t out = 0;
  for (std::size_t s : {alignof(T)...}) out = s > out ? s : out;
  return out;
}

struct RobustSvf {
  alignas(max_align<Svf<1, 0>, Svf<2, 0>, Svf<1, kBasis>, Svf<2, kBasis>>()) unsigned char
      core[max_size<Svf<1, 0>, Svf<2, 0>, Svf<1, kBasis>, Svf<2, kBasis>>()];
  float flow_ref{0};
  float exponent{0};  // order 2 with flow: the m of phi
  float max_ratio{1};
  float ratio_min{0};  // flows seen, relative to flow_ref
  float ratio_max{0};
  std::uint32_t settle_rows{0};  // rows skipped after a gap: ceil(25 tf / Ts)
  std::uint64_t transient_samples{0};  // the core's start-up window, (60 + 2 m) tf / Ts rows
  int variant{-1};  // 0: order 1, 1: order 2, 2: order 1 + flow, 3: order 2 + flow; -1: none

  template <int Order, int Basis>
  Svf<Order, Basis>* as() noexcept {
    return std::launder(reinterpret_cast<Svf<Order, Basis>*>(core));
  }
  template <int Order, int Basis>
  const Svf<Order, Basis>* as() const noexcept {
    return std::launder(reinterpret_cast<const Svf<Order, Basis>*>(core));
  }
};

static_assert(sizeof(RobustSvf) <= sizeof(dp_svf_instance_f32::storage),
              "DP_SVF_INSTANCE_BYTES too small");
static_assert(alignof(RobustSvf) <= alignof(dp_svf_instance_f32), "dp_svf_instance_f32 alignment");
static_assert(std::is_trivially_destructible<Svf<2, kBasis>>::value, "SVF needs a destructor");

RobustSvf* svf(dp_svf_instance_f32* instance) noexcept {
  return std::launder(reinterpret_cast<RobustSvf*>(instance->storage.words));
}
const RobustSvf* svf(const dp_svf_instance_f32* instance) noexcept {
  return std::launder(reinterpret_cast<const RobustSvf*>(instance->storage.words));
}

bool finite_positive(float v) noexcept { return v > 0.0f && std::isfinite(v); }

// Time constants of 1 + c s (+ d s^2), largest first; false unless real and positive.
bool roots(float c, float d, int order, float taus[2]) noexcept {
  taus[0] = taus[1] = 0.0f;
  if (!finite_positive(c)) return false;
  if (order == 1) {
    taus[0] = c;
    return true;
  }
  if (!finite_positive(d)) return false;
  float disc = c * c - 4.0f * d;
  if (disc < 0.0f && -disc <= 64.0f * 1.1920929e-7f * c * c) disc = 0.0f;  // a double pole
  if (disc < 0.0f) return false;
  taus[0] = 0.5f * (c + std::sqrt(disc));
  taus[1] = d / taus[0];
  return finite_positive(taus[0]) && finite_positive(taus[1]);
}

// Basis psi' = sum_j c_j r^m_j of a scheduled solve (c_K = 1).
float basis_psi(const float coefficients[kBasis], float ratio) noexcept {
  float b[kBasis];
  basis_weights(ratio, b);
  float sum = 0.0f;
  for (int j = 0; j < kBasis; ++j) sum += coefficients[j] * b[j];
  return sum;
}

template <int Order, int Basis>
dp_status solve_variant(RobustSvf* s, dp_svf_result_f32* out) noexcept {
  const auto solved = s->as<Order, Basis>()->solve();
  out->order = Order;
  out->rows = solved.rows;
  out->eigenvalue_ratio = solved.eigenvalue_ratio;
  // Within the start-up window the float solve must project large filter transients out of
  // float moments, and its estimates are unreliable (drive cycle: refused or off by several
  // percent, and an order-2 estimate would feed phi's exponent): refused until the window
  // has passed (with forgetting the transients have decayed by then as well).
  if (s->as<Order, Basis>()->samples() < s->transient_samples) {
    return DP_STATUS_INSUFFICIENT_EXCITATION;
  }
  // With a schedule basis the core normalises theta by the last basis coefficient, whose sign
  // is not known in advance: a relation with a_K < 0 comes back with negative polynomials and
  // status infeasible. Dividing by psi'(flow_ref) below restores the sign, so only the other
  // refusals (no relation at all: theta left zero) stop a scheduled solve here.
  const bool sign_only = Basis > 0 && solved.status == dualprobe::Status::infeasible &&
                         solved.theta.allFinite() &&
                         solved.theta[solved.theta.size() - 1] == -1.0f;
  if (solved.status != dualprobe::Status::ok && !sign_only) {
    return static_cast<dp_status>(solved.status);
  }
  if (!(solved.eigenvalue_ratio <= s->max_ratio) || !std::isfinite(solved.eigenvalue_ratio)) {
    return DP_STATUS_INSUFFICIENT_EXCITATION;  // a relation, but not a single identifiable one
  }
  float p1[2] = {solved.polynomial1[0], Order == 2 ? solved.polynomial1[Order - 1] : 0.0f};
  float p2[2] = {solved.polynomial2[0], Order == 2 ? solved.polynomial2[Order - 1] : 0.0f};
  float exponent = 0.0f;
  if constexpr (Basis > 0) {
    // theta = [dynamic..., -c_1, ..., -c_{K-1}, -1]: psi' = sum c_j b_j, normalised at r = 1.
    constexpr int first = 2 * Order;
    float c[kBasis];
    for (int j = 0; j < kBasis; ++j) c[j] = -solved.theta[first + j];
    const float at_ref = basis_psi(c, 1.0f);  // negative when a_K < 0: the division fixes it
    if (!(std::fabs(at_ref) > 0.0f) || !std::isfinite(at_ref)) return DP_STATUS_INFEASIBLE;
    for (int j = 0; j < Order; ++j) {
      p1[j] /= at_ref;
      p2[j] /= at_ref;
    }
    // m: least-squares slope of log psi' on log r over the flows seen (log-spaced grid).
    const float lo = det_log(s->ratio_min);
    const float hi = det_log(s->ratio_max);
    if (!(hi - lo > 0.05f)) return DP_STATUS_INSUFFICIENT_EXCITATION;  // flow did not move
    float sx = 0.0f, sy = 0.0f, sxx = 0.0f, sxy = 0.0f;
    for (int i = 0; i < kExponentGrid; ++i) {
      const float x = lo + (hi - lo) * float(i) / float(kExponentGrid - 1);
      const float psi = basis_psi(c, det_exp(x)) / at_ref;  // psi(flow_ref) = 1
      if (!finite_positive(psi)) return DP_STATUS_INFEASIBLE;
      const float y = det_log(psi);
      sx += x;
      sy += y;
      sxx += x * x;
      sxy += x * y;
    }
    const float n = float(kExponentGrid);
    exponent = (n * sxy - sx * sy) / (n * sxx - sx * sx);
    if (!std::isfinite(exponent) || exponent < 0.0f || exponent > 2.0f) {
      return DP_STATUS_INFEASIBLE;
    }
  }
  float taus1[2];
  float taus2[2];
  if (!roots(p1[0], p1[1], Order, taus1) || !roots(p2[0], p2[1], Order, taus2)) {
    return DP_STATUS_INFEASIBLE;
  }
  for (int j = 0; j < 2; ++j) {
    out->tau1[j] = taus1[j];
    out->tau2[j] = taus2[j];
  }
  out->exponent = exponent;
  if (Basis > 0 && Order == 2) s->exponent = exponent;  // phi of the next samples
  return DP_STATUS_OK;
}

// ---- Kalman ------------------------------------------------------------------------------

constexpr int kWindow = DP_KALMAN_MAX_WINDOW;
template <int N>
using Kalman = dualprobe::KalmanReconstructor<float, N, 1, kWindow>;

struct RobustKalman {
  alignas(max_align<Kalman<3>, Kalman<5>>()) unsigned char core[max_size<Kalman<3>, Kalman<5>>()];
  float ts{1};
  float taus[2][2]{};
  float variance[2]{};
  float intensity{0};
  int order[2]{1, 1};
  int states{0};  // 3 (Kalman<3>) or 5 (Kalman<5>, 4 or 5 used); 0: not configured

  template <int N>
  Kalman<N>* as() noexcept {
    return std::launder(reinterpret_cast<Kalman<N>*>(core));
  }
  template <int N>
  const Kalman<N>* as() const noexcept {
    return std::launder(reinterpret_cast<const Kalman<N>*>(core));
  }
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
  if (status != dualprobe::Status::ok) return static_cast<dp_status>(status);
  *gas = out;
  return DP_STATUS_OK;
}

bool valid_taus(const float taus[2], int order) noexcept {
  return finite_positive(taus[0]) && (order == 1 || finite_positive(taus[1]));
}

}  // namespace

extern "C" {

dp_status dp_svf_init_f32(dp_svf_instance_f32* instance, const dp_svf_config_f32* config) {
  if (instance == nullptr) return DP_STATUS_INVALID_ARGUMENT;
  std::memset(instance, 0, sizeof(*instance));
  RobustSvf* s = new (instance->storage.words) RobustSvf();
  if (config == nullptr) return DP_STATUS_INVALID_ARGUMENT;
  const bool flow = config->flow_ref != 0.0f;
  const float floor = config->quantisation * config->quantisation / 12.0f;
  const bool ok = (config->order == 1u || config->order == 2u) &&
                  (!flow || finite_positive(config->flow_ref)) &&
                  config->quantisation >= 0.0f && std::isfinite(config->quantisation) &&
                  config->exponent >= 0.0f && config->exponent <= 2.0f &&
                  config->max_eigenvalue_ratio > 0.0f && config->max_eigenvalue_ratio <= 1.0f;
  if (!ok) return DP_STATUS_INVALID_ARGUMENT;
  dualprobe::SvfConfig<float> core;
  core.sample_interval = config->sample_interval;
  core.filter_time_constant = config->filter_time_constant;
  core.sigma1 = std::sqrt(config->sigma1 * config->sigma1 + floor);
  core.sigma2 = std::sqrt(config->sigma2 * config->sigma2 + floor);
  core.forgetting = config->forgetting;
  if (!(config->sigma1 >= 0.0f) || !(config->sigma2 >= 0.0f)) return DP_STATUS_INVALID_ARGUMENT;
  const int variant = int(config->order) - 1 + (flow ? 2 : 0);
  dualprobe::Status status = dualprobe::Status::invalid_argument;
  switch (variant) {
    case 0: status = (new (s->core) Svf<1, 0>())->configure(core); break;
    case 1: status = (new (s->core) Svf<2, 0>())->configure(core); break;
    case 2: status = (new (s->core) Svf<1, kBasis>())->configure(core); break;
    default: status = (new (s->core) Svf<2, kBasis>())->configure(core); break;
  }
  if (status != dualprobe::Status::ok) return DP_STATUS_INVALID_ARGUMENT;
  s->flow_ref = flow ? config->flow_ref : 0.0f;
  s->exponent = config->exponent;
  s->max_ratio = config->max_eigenvalue_ratio;
  s->variant = variant;
  s->settle_rows = std::uint32_t(std::ceil(25.0f * config->filter_time_constant /
                                           config->sample_interval));
  s->transient_samples = std::uint64_t(
      std::ceil((60.0 + 2.0 * (config->order + 1)) * double(config->filter_time_constant) /
                double(config->sample_interval))) + 1u;
  return DP_STATUS_OK;
}

void dp_svf_break_chain_f32(dp_svf_instance_f32* instance) {
  if (instance == nullptr) return;
  RobustSvf* s = svf(instance);
  switch (s->variant) {
    case 0: s->as<1, 0>()->break_chain(s->settle_rows); break;
    case 1: s->as<2, 0>()->break_chain(s->settle_rows); break;
    case 2: s->as<1, kBasis>()->break_chain(s->settle_rows); break;
    case 3: s->as<2, kBasis>()->break_chain(s->settle_rows); break;
    default: break;
  }
}

void dp_svf_reset_f32(dp_svf_instance_f32* instance) {
  if (instance == nullptr) return;
  RobustSvf* s = svf(instance);
  switch (s->variant) {
    case 0: s->as<1, 0>()->reset(); break;
    case 1: s->as<2, 0>()->reset(); break;
    case 2: s->as<1, kBasis>()->reset(); break;
    case 3: s->as<2, kBasis>()->reset(); break;
    default: return;
  }
  s->ratio_min = s->ratio_max = 0.0f;
}

dp_status dp_svf_update_f32(dp_svf_instance_f32* instance, float t1, float t2, float flow) {
  if (instance == nullptr) return DP_STATUS_INVALID_ARGUMENT;
  RobustSvf* s = svf(instance);
  if (s->variant < 0) return DP_STATUS_INVALID_ARGUMENT;
  if (!std::isfinite(t1) || !std::isfinite(t2)) return DP_STATUS_NON_FINITE_INPUT;
  if (s->variant == 0) return static_cast<dp_status>(s->as<1, 0>()->update(t1, t2));
  if (s->variant == 1) return static_cast<dp_status>(s->as<2, 0>()->update(t1, t2));
  if (!std::isfinite(flow)) return DP_STATUS_NON_FINITE_INPUT;
  const float ratio = flow / s->flow_ref;
  if (!finite_positive(ratio)) return DP_STATUS_INVALID_ARGUMENT;
  float weights[kBasis];
  basis_weights(ratio, weights);
  dualprobe::Status status;
  if (s->variant == 2) {
    status = s->as<1, kBasis>()->update(t1, t2, weights, 1.0f);
  } else {
    const float phi = det_exp(-s->exponent * det_log(ratio));
    status = s->as<2, kBasis>()->update(t1, t2, weights, phi);
  }
  if (status == dualprobe::Status::ok) {
    const bool first = s->ratio_max == 0.0f;
    s->ratio_min = first || ratio < s->ratio_min ? ratio : s->ratio_min;
    s->ratio_max = first || ratio > s->ratio_max ? ratio : s->ratio_max;
  }
  return static_cast<dp_status>(status);
}

dp_status dp_svf_solve_f32(dp_svf_instance_f32* instance, dp_svf_result_f32* result) {
  if (instance == nullptr || result == nullptr) return DP_STATUS_INVALID_ARGUMENT;
  RobustSvf* s = svf(instance);
  dp_svf_result_f32 out{};
  dp_status status = DP_STATUS_INVALID_ARGUMENT;
  switch (s->variant) {
    case 0: status = solve_variant<1, 0>(s, &out); break;
    case 1: status = solve_variant<2, 0>(s, &out); break;
    case 2: status = solve_variant<1, kBasis>(s, &out); break;
    case 3: status = solve_variant<2, kBasis>(s, &out); break;
    default: break;
  }
  out.status = status;
  if (status != DP_STATUS_OK) {  // only the diagnostics survive a refusal
    const float ratio = out.eigenvalue_ratio;
    const float rows = out.rows;
    const uint32_t order = out.order;
    out = dp_svf_result_f32{};
    out.status = status;
    out.eigenvalue_ratio = ratio;
    out.rows = rows;
    out.order = order;
  }
  *result = out;
  return status;
}

float dp_svf_schedule_f32(const dp_svf_instance_f32* instance, const dp_svf_result_f32* result,
                          float flow) {
  if (instance == nullptr || result == nullptr || result->status != DP_STATUS_OK) return 1.0f;
  const RobustSvf* s = svf(instance);
  if (s->variant < 2 || !finite_positive(flow)) return 1.0f;
  const float psi = det_exp(result->exponent * det_log(flow / s->flow_ref));
  return finite_positive(psi) ? psi : 1.0f;
}

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
      !finite_positive(config->intensity) || config->window > uint32_t(kWindow)) {
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
  k->states = states;
  return DP_STATUS_OK;
}

void dp_kalman_reset_f32(dp_kalman_instance_f32* instance) {
  if (instance == nullptr) return;
  RobustKalman* k = kalman(instance);
  if (k->states == 3) k->as<3>()->reset();
  if (k->states == 5) k->as<5>()->reset();
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

}  // extern "C"
