/* The noise-robust loop (issue 13): ADC counts -> Callendar-Van Dusen -> open/short detection
 * -> SVF cross-relation estimator every healthy tick (with the flow channel when configured)
 * -> a solve every solve_every ticks -> the causal Kalman reconstruction every healthy tick,
 * scheduled with psi = (flow/flow_ref)^m of the last published solve, and its fixed-lag output
 * (the gas of `lag` ticks ago from the samples up to now) when lag > 0.
 *
 * A solve is published (Kalman retuned, FLAG_TAUS_VALID) only when it is ok, identifiable
 * (eigenvalue-ratio gate in the C API) and plausible (every time constant within
 * [tau_min, tau_max]); otherwise the last published result stays in force, so a stretch
 * without excitation never replaces a good estimate by a diverged one.
 *
 * Faults: as the difference loop (firmware.c). The estimator and the Kalman pause; the Kalman
 * restarts from the next healthy sample after `resume_after` healthy ticks (its offset and
 * spread re-initialised); the SVF's chain is broken (dp_svf_break_chain_f32: its cascades join
 * the gap in one interval and the next 25 tf/Ts rows, while that transient decays, are not
 * accumulated; the accumulated moments survive). */
#include <math.h>
#include <string.h>

#include "firmware.h"

dp_status firmware_robust_init(firmware_state *state) {
  const firmware_config *c = &state->config;
  const dp_svf_config_f32 svf = {c->sample_interval, c->filter_time_constant, c->order,
                                 c->sigma1,          c->sigma2,               c->quantisation,
                                 c->forgetting,      c->flow_ref,             c->exponent,
                                 c->max_eigenvalue_ratio};
  dp_status status = dp_svf_init_f32(&state->svf, &svf);
  if (status != DP_STATUS_OK) return status;
  state->taus_valid = c->initial_tau1 > 0.0f && c->initial_tau2 > 0.0f;
  /* Initial time constants (calibration) at the reference flow, both stages alike for order 2
   * (a placeholder split 0.8 / 0.2 of the given sum); placeholders 1 s until a solve. */
  const float tau1 = state->taus_valid ? c->initial_tau1 : 1.0f;
  const float tau2 = state->taus_valid ? c->initial_tau2 : 1.0f;
  dp_kalman_config_f32 kalman;
  memset(&kalman, 0, sizeof kalman);
  kalman.sample_interval = c->sample_interval;
  kalman.order1 = c->order;
  kalman.order2 = c->order;
  kalman.taus1[0] = c->order == 2u ? 0.8f * tau1 : tau1;
  kalman.taus1[1] = 0.2f * tau1;
  kalman.taus2[0] = c->order == 2u ? 0.8f * tau2 : tau2;
  kalman.taus2[1] = 0.2f * tau2;
  kalman.sigma1 = c->sigma1;
  kalman.sigma2 = c->sigma2;
  kalman.quantisation = c->quantisation;
  kalman.intensity = c->intensity;
  kalman.window = c->window;
  kalman.false_alarm = c->false_alarm;
  kalman.lag = c->lag;
  status = dp_kalman_init_f32(&state->kalman, &kalman);
  if (status != DP_STATUS_OK) return status;
  memset(&state->good, 0, sizeof state->good);
  state->good.status = DP_STATUS_NOT_READY;
  state->paused = 0u;
  return DP_STATUS_OK;
}

static int plausible(const firmware_config *c, const dp_svf_result_f32 *r) {
  const uint32_t stages = r->order == 2u ? 2u : 1u;
  for (uint32_t j = 0; j < stages; ++j) {
    if (!(r->tau1[j] >= c->tau_min && r->tau1[j] <= c->tau_max)) return 0;
    if (!(r->tau2[j] >= c->tau_min && r->tau2[j] <= c->tau_max)) return 0;
  }
  return 1;
}

void firmware_robust_tick(firmware_state *state, uint32_t counts1, uint32_t counts2, float flow,
                          tick_output *out) {
  const firmware_config *config = &state->config;
  float t1;
  float t2;
  uint32_t flags = firmware_read_channels(counts1, counts2, &t1, &t2);
  out->gas = firmware_nan();
  out->gas_lagged = firmware_nan();
  out->published = 0u;
  if (flags != 0u) {
    if (!state->paused) {
      dp_svf_break_chain_f32(&state->svf);
      dp_kalman_reset_f32(&state->kalman);
      state->paused = 1u;
    }
    state->healthy_run = 0u;
  } else if (state->paused) {
    state->healthy_run += 1u;
    if (state->healthy_run >= config->resume_after) state->paused = 0u;
  }
  const int flow_ok = config->flow_ref == 0.0f || (isfinite(flow) && flow > 0.0f);
  if (state->paused) {
    flags |= FLAG_PAUSED;
  } else if (flow_ok) {
    /* Temperatures from the CVD inverse are finite here and the flow was checked. */
    (void)dp_svf_update_f32(&state->svf, t1, t2, flow);
    if (state->taus_valid) {
      const float psi = dp_svf_schedule_f32(&state->svf, &state->good, flow);
      float gas = 0.0f;
      if (dp_kalman_update_f32(&state->kalman, t1, t2, psi, &gas) == DP_STATUS_OK) {
        out->gas = gas;
        flags |= FLAG_GAS_VALID;
        float lagged = 0.0f;
        if (dp_kalman_lagged_f32(&state->kalman, &lagged, NULL) == DP_STATUS_OK) {
          out->gas_lagged = lagged;
        }
      }
    }
  } else {
    flags |= FLAG_PAUSED; /* an invalid flow reading: neither the estimator nor the Kalman */
  }

  state->tick += 1u;
  if (state->tick % config->solve_every == 0u) {
    flags |= FLAG_SOLVED;
    if (dp_svf_solve_f32(&state->svf, &out->robust) == DP_STATUS_OK &&
        plausible(config, &out->robust) &&
        dp_kalman_retune_f32(&state->kalman, out->robust.tau1, out->robust.tau2) ==
            DP_STATUS_OK) {
      state->good = out->robust;
      state->taus_valid = 1u;
      out->published = 1u;
    }
  }
  if (state->taus_valid) flags |= FLAG_TAUS_VALID;
  out->tick = state->tick - 1u;
  out->flags = flags;
  out->t1 = t1;
  out->t2 = t2;
}
