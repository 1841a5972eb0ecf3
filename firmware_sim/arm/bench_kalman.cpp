// C entry points of the bench around a float KalmanFirstOrder (see bench_kalman.h). The
// instance lives in a static byte buffer and is constructed by placement new in
// bench_kalman_init: a global object would need a static initialiser (.init_array, refused
// by mcu.ld), and placement new needs no heap.
#include "bench_kalman.h"

#include <new>

#include "dualprobe/kalman.hpp"

namespace {
using Kalman = dualprobe::KalmanFirstOrder<float>;
alignas(Kalman) unsigned char g_storage[sizeof(Kalman)];
Kalman* g_kalman = nullptr;
}  // namespace

extern "C" int bench_kalman_init(float sample_interval, float tau1, float tau2, float sigma1,
                                 float sigma2, float intensity) {
  if (g_kalman == nullptr) g_kalman = new (g_storage) Kalman();
  dualprobe::KalmanConfig<float> config;
  config.sample_interval = sample_interval;
  config.taus1[0] = tau1;
  config.taus2[0] = tau2;
  config.sigma1 = sigma1;
  config.sigma2 = sigma2;
  config.intensity = intensity;
  return static_cast<int>(g_kalman->configure(config));
}

extern "C" int bench_kalman_update(float t1, float t2, float* gas) {
  return static_cast<int>(g_kalman->update(t1, t2, gas));
}

extern "C" uint32_t bench_kalman_bytes(void) { return static_cast<uint32_t>(sizeof(Kalman)); }

extern "C" uint32_t bench_kalman_jumps(void) {
  return g_kalman == nullptr ? 0u : g_kalman->jump_count();
}
