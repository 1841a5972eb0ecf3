/* The causal Kalman reconstruction (cpp/include/dualprobe/kalman.hpp) for the instruction-count
 * bench: C entry points around one statically allocated float instance in the ECU
 * configuration (first-order pair, random-walk gas, GLR window of 64 intervals). */
#ifndef DUALPROBE_BENCH_KALMAN_H
#define DUALPROBE_BENCH_KALMAN_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* 0 on success (a valid configuration), else the core's Status code. */
int bench_kalman_init(float sample_interval, float tau1, float tau2, float sigma1, float sigma2,
                      float intensity);
/* One sample pair; the measured function. Returns the Status code, writes the gas. */
int bench_kalman_update(float t1, float t2, float *gas);
/* sizeof the instance, and jumps detected so far. */
uint32_t bench_kalman_bytes(void);
uint32_t bench_kalman_jumps(void);

#ifdef __cplusplus
}
#endif

#endif
