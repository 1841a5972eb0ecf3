// Internal helpers of the noise-robust C API (dualprobe_svf_c.cpp, dualprobe_kalman_c.cpp):
// deterministic float exp / expm1 / log and storage helpers. Not installed, not public.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <new>

namespace dualprobe {
namespace c_detail {

inline bool finite_positive(float v) noexcept { return v > 0.0f && std::isfinite(v); }

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

// The object built with placement new in raw storage (sized by max_size / max_align).
template <typename T>
T* placed(unsigned char* storage) noexcept {
  return std::launder(reinterpret_cast<T*>(storage));
}
template <typename T>
const T* placed(const unsigned char* storage) noexcept {
  return std::launder(reinterpret_cast<const T*>(storage));
}

// libm's expf/expm1f/logf differ in the last bit between glibc and newlib; on the per-sample
// path (the flow schedule, the Kalman's per-interval model) one ulp grows into a different
// solve status and so a different run. These use only + - * / and IEEE sqrt-free bit
// manipulation, so host and M4F round identically (with -ffp-contract=off); accuracy 2-3 ulp,
// far below everything they feed (time constants known to 1e-3 at best).
inline float bits_to_float(std::uint32_t bits) noexcept {
  float value;
  std::memcpy(&value, &bits, sizeof value);
  return value;
}

// e^r - 1 for |r| <= ln2/2 (Taylor to degree 8: truncation r^9/9! < 2e-11), no cancellation.
inline float expm1_reduced(float r) noexcept {
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
inline float reduce(float x, int* n) noexcept {
  const float k = x * 1.44269504f;
  *n = int(k + (k >= 0.0f ? 0.5f : -0.5f));
  const float fn = float(*n);
  return (x - fn * 0.693145751953125f) - fn * 1.428606820309417232e-6f;
}

inline float det_exp(float x) noexcept {
  if (!(x < 88.0f)) return x != x ? x : bits_to_float(0x7F800000u);  // NaN, +inf
  if (x < -87.0f) return 0.0f;
  int n = 0;
  const float r = reduce(x, &n);
  return (1.0f + expm1_reduced(r)) * bits_to_float(std::uint32_t(n + 127) << 23);
}

inline float det_expm1(float x) noexcept {
  if (x > -0.34657359f && x < 0.34657359f) return expm1_reduced(x);
  return det_exp(x) - 1.0f;
}

// log(x) for finite x > 0: x = m 2^e with m in [sqrt(1/2), sqrt(2)), log m = 2 atanh(s),
// s = (m - 1)/(m + 1), |s| <= 0.1716: series to s^11 (truncation < 1e-10).
inline float det_log(float x) noexcept {
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

}  // namespace c_detail
}  // namespace dualprobe
