/* C consumer of the installed dualprobe::c: a first-order pair through the C API. */
#include <math.h>
#include <stdio.h>

#include "dualprobe/dualprobe.h"

int main(void) {
  dp_diff_instance_f32 estimator;
  const dp_diff_config_f32 config = {1.0f, DP_METHOD_LS, 0.0f, 0.0f, 1.0f};
  const float a1 = expf(-1.0f / 5.0f), a2 = expf(-1.0f / 15.0f);
  float t1 = 0.0f, t2 = 0.0f;
  dp_diff_result_f32 result;
  int k;
  if (dp_diff_init_f32(&estimator, &config) != DP_STATUS_OK) return 1;
  for (k = 0; k < 400; ++k) {
    const float gas = (k / 40) % 2 == 0 ? 10.0f : -10.0f;
    dp_diff_update_f32(&estimator, t1, t2);
    t1 = a1 * t1 + (1.0f - a1) * gas;
    t2 = a2 * t2 + (1.0f - a2) * gas;
  }
  if (dp_diff_solve_f32(&estimator, &result) != DP_STATUS_OK) return 1;
  printf("consumer_c: %s tau1=%.3f tau2=%.3f\n", dp_status_string(result.status),
         (double)result.tau1, (double)result.tau2);
  /* float data from the float recursion: 1 % */
  return fabsf(result.tau1 - 5.0f) < 0.05f && fabsf(result.tau2 - 15.0f) < 0.15f ? 0 : 1;
}
