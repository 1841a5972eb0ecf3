#include "pt100.h"

#include <math.h>

float pt100_resistance(float temperature_c) {
  const float t = temperature_c;
  float ratio = 1.0f + PT100_A * t + PT100_B * t * t;
  if (t < 0.0f) ratio += PT100_C * (t - 100.0f) * t * t * t;
  return PT100_R0 * ratio;
}

float pt100_temperature(float resistance_ohm) {
  /* x = R/R0 - 1, then the quadratic root written without cancellation:
   * T = 2x / (A + sqrt(A^2 + 4 B x)) (B < 0, and A^2 + 4Bx > 0 over the whole range). */
  const float x = (resistance_ohm - PT100_R0) / PT100_R0;
  const float discriminant = PT100_A * PT100_A + 4.0f * PT100_B * x;
  float t = 2.0f * x / (PT100_A + sqrtf(discriminant > 0.0f ? discriminant : 0.0f));
  if (x < 0.0f) {
    /* Below 0 C the C term adds up to 0.04 K; three Newton steps from the quadratic root
     * converge to float precision (quadratic convergence from a 0.04 K start). A fixed count
     * keeps the cost deterministic. */
    for (int i = 0; i < 3; ++i) {
      const float t2 = t * t;
      const float f = PT100_A * t + PT100_B * t2 + PT100_C * (t - 100.0f) * t2 * t - x;
      const float df =
          PT100_A + 2.0f * PT100_B * t + PT100_C * (4.0f * t2 * t - 300.0f * t2);
      t -= f / df;
    }
  }
  return t;
}
