// The SVF half of the noise-robust C API (dualprobe.h, issue 13): the cross-relation
// estimator with an optional flow schedule, float only, solve included (SolveScalar = float):
// no double arithmetic per sample or per solve, so nothing runs in soft-float on a Cortex-M4F.
// Each C instance is raw storage holding one core object built with placement new.
#include <cmath>
#include <cstdint>
#include <cstring>
#include <new>
#include <type_traits>

#include "dualprobe/dualprobe.h"
#include "dualprobe/status.hpp"
#include "dualprobe/svf_estimator.hpp"
#include "robust_detail.hpp"

namespace {

using namespace dualprobe::c_detail;

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

}  // extern "C"
