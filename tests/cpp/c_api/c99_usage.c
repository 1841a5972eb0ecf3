/* The C API from strict C99 (-std=c99 -Wpedantic -Werror): every declaration of dualprobe.h
 * compiles as C, instances live in static storage, and a short first-order stream runs
 * through init / update / solve / reconstruct with the documented statuses. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "dualprobe/dualprobe.h"

static dp_diff_instance_f32 g_estimator;
static dp_recon_instance_f32 g_reconstruction;

int main(void) {
  const dp_diff_config_f32 config = {0.1f, DP_METHOD_TLS, 0.0f, 0.0f, 1.0f};
  const dp_recon_config_f32 recon = {0.1f, 1.0f, 1.0f, DP_SOURCE_WEIGHTED, 0.0f};
  const float a1 = expf(-0.1f / 2.0f), a2 = expf(-0.1f / 6.0f);
  float t1 = 20.0f, t2 = 20.0f, gas = 0.0f;
  dp_diff_result_f32 result;
  int k;
  if (dp_diff_init_f32(&g_estimator, &config) != DP_STATUS_OK) return 1;
  if (dp_recon_init_f32(&g_reconstruction, &recon) != DP_STATUS_OK) return 1;
  for (k = 0; k < 3000; ++k) {
    const float tg = (k / 300) % 2 == 0 ? 80.0f : 30.0f; /* steps every 30 s */
    if (dp_diff_update_f32(&g_estimator, t1, t2) != DP_STATUS_OK) return 1;
    t1 = a1 * t1 + (1.0f - a1) * tg;
    t2 = a2 * t2 + (1.0f - a2) * tg;
  }
  if (dp_diff_solve_f32(&g_estimator, &result) != DP_STATUS_OK) {
    printf("solve: %s\n", dp_status_string(result.status));
    return 1;
  }
  /* Float data from the float recursion: time constants to 1 % */
  if (fabsf(result.tau1 - 2.0f) > 0.02f || fabsf(result.tau2 - 6.0f) > 0.06f) {
    printf("tau1 %g tau2 %g\n", (double)result.tau1, (double)result.tau2);
    return 1;
  }
  if (dp_recon_set_time_constants_f32(&g_reconstruction, result.tau1, result.tau2) != DP_STATUS_OK)
    return 1;
  if (dp_recon_update_f32(&g_reconstruction, 50.0f, 50.0f, &gas) != DP_STATUS_NOT_READY) return 1;
  if (dp_recon_update_f32(&g_reconstruction, 50.0f, 50.0f, &gas) != DP_STATUS_OK) return 1;
  if (fabsf(gas - 50.0f) > 1e-3f) return 1;
  if (dp_diff_update_f32(&g_estimator, NAN, 1.0f) != DP_STATUS_NON_FINITE_INPUT) return 1;
  /* In C any int may sit in an enum: out-of-range values are handled, not undefined. */
  if (strcmp(dp_status_string((dp_status)42), "unknown") != 0) return 1;
  {
    dp_diff_config_f32 bad = config;
    bad.method = (dp_method)7;
    if (dp_diff_init_f32(&g_estimator, &bad) != DP_STATUS_INVALID_ARGUMENT) return 1;
  }
  printf("c99 usage ok: tau1 %.4f tau2 %.4f\n", (double)result.tau1, (double)result.tau2);
  return 0;
}
