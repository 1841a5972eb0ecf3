#include "firmware.h"

#include <string.h>

#include "platform.h"

/* ---- calibration block --------------------------------------------------------------- */

static uint32_t read_u32(const uint8_t *p) {
  return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

static float read_f32(const uint8_t *p) {
  const uint32_t bits = read_u32(p);
  float value;
  memcpy(&value, &bits, sizeof value);
  return value;
}

int firmware_parse_header(const uint8_t header[FIRMWARE_HEADER_BYTES], firmware_config *config) {
  if (read_u32(header + 0) != FIRMWARE_MAGIC) return -1;
  if (read_u32(header + 4) != FIRMWARE_VERSION && read_u32(header + 4) != FIRMWARE_VERSION_ROBUST) {
    return -2;
  }
  config->ticks = read_u32(header + 8);
  config->sample_interval = read_f32(header + 12);
  config->method = (dp_method)read_u32(header + 16);
  config->sigma1 = read_f32(header + 20);
  config->sigma2 = read_f32(header + 24);
  config->forgetting = read_f32(header + 28);
  config->solve_every = read_u32(header + 32);
  config->resume_after = read_u32(header + 36);
  config->source = (dp_source)read_u32(header + 40);
  config->lowpass_tau = read_f32(header + 44);
  config->initial_tau1 = read_f32(header + 48);
  config->initial_tau2 = read_f32(header + 52);
  if (config->solve_every == 0u) return -3;
  const uint32_t version = read_u32(header + 4);
  config->version = version;
  config->estimator = ESTIMATOR_DIFFERENCE;
  return 0;
}

int firmware_parse_header2(const uint8_t extra[FIRMWARE_HEADER2_EXTRA_BYTES],
                           firmware_config *config) {
  const uint32_t estimator = read_u32(extra + 0);
  if (estimator > (uint32_t)ESTIMATOR_SVF) return -4;
  config->estimator = (firmware_estimator)estimator;
  config->order = read_u32(extra + 4);
  config->filter_time_constant = read_f32(extra + 8);
  config->quantisation = read_f32(extra + 12);
  config->flow_ref = read_f32(extra + 16);
  config->exponent = read_f32(extra + 20);
  config->max_eigenvalue_ratio = read_f32(extra + 24);
  config->intensity = read_f32(extra + 28);
  config->window = read_u32(extra + 32);
  config->false_alarm = read_f32(extra + 36);
  config->tau_min = read_f32(extra + 40);
  config->tau_max = read_f32(extra + 44);
  config->lag = read_u32(extra + 48);
  if (!(config->tau_min >= 0.0f) || !(config->tau_max > config->tau_min)) return -5;
  return 0;
}

/* ---- the loop ------------------------------------------------------------------------ */

static float quiet_nan(void) {
  /* The same bit pattern on every target (x86's default NaN has the sign bit set, ARM's not),
   * so host and M4F outputs compare byte for byte. */
  const uint32_t bits = 0x7FC00000u;
  float value;
  memcpy(&value, &bits, sizeof value);
  return value;
}

dp_status firmware_init(firmware_state *state, const firmware_config *config) {
  memset(state, 0, sizeof *state);
  state->config = *config;
  if (config->estimator == ESTIMATOR_SVF) return firmware_robust_init(state);
  const dp_diff_config_f32 diff = {config->sample_interval, config->method, config->sigma1,
                                   config->sigma2, config->forgetting};
  dp_status status = dp_diff_init_f32(&state->estimator, &diff);
  if (status != DP_STATUS_OK) return status;
  state->taus_valid = config->initial_tau1 > 0.0f && config->initial_tau2 > 0.0f;
  /* Until a time constant is known the reconstruction is configured with placeholders and
   * not used (FLAG_GAS_VALID stays clear). */
  const dp_recon_config_f32 recon = {config->sample_interval,
                                     state->taus_valid ? config->initial_tau1 : 1.0f,
                                     state->taus_valid ? config->initial_tau2 : 1.0f,
                                     config->source, config->lowpass_tau};
  status = dp_recon_init_f32(&state->reconstruction, &recon);
  if (status != DP_STATUS_OK) return status;
  state->paused = 0u;
  return DP_STATUS_OK;
}

uint32_t firmware_read_channels(uint32_t counts1, uint32_t counts2, float *t1, float *t2) {
  uint32_t flags = 0u;
  *t1 = quiet_nan();
  *t2 = quiet_nan();
  const channel_state ch1 = adc_read_channel(counts1, t1);
  const channel_state ch2 = adc_read_channel(counts2, t2);
  if (ch1 == CHANNEL_OPEN) flags |= FLAG_CH1_OPEN;
  if (ch1 == CHANNEL_SHORT) flags |= FLAG_CH1_SHORT;
  if (ch2 == CHANNEL_OPEN) flags |= FLAG_CH2_OPEN;
  if (ch2 == CHANNEL_SHORT) flags |= FLAG_CH2_SHORT;
  if (ch1 != CHANNEL_OK) *t1 = quiet_nan();
  if (ch2 != CHANNEL_OK) *t2 = quiet_nan();
  return flags;
}

float firmware_nan(void) { return quiet_nan(); }

void firmware_tick_flow(firmware_state *state, uint32_t counts1, uint32_t counts2, float flow,
                        tick_output *out) {
  if (state->config.estimator == ESTIMATOR_SVF) {
    firmware_robust_tick(state, counts1, counts2, flow, out);
  } else {
    firmware_tick(state, counts1, counts2, out);
  }
}

void firmware_tick(firmware_state *state, uint32_t counts1, uint32_t counts2, tick_output *out) {
  const firmware_config *config = &state->config;
  float t1;
  float t2;
  uint32_t flags = firmware_read_channels(counts1, counts2, &t1, &t2);
  out->published = 0u;

  out->gas = quiet_nan();
  out->gas_lagged = quiet_nan();
  if (flags != 0u) {
    /* Fault: stop feeding both the estimator and the reconstruction; the next healthy sample
     * must not be differenced against the last one before the fault. */
    if (!state->paused) {
      dp_diff_break_chain_f32(&state->estimator);
      dp_recon_reset_f32(&state->reconstruction);
      state->paused = 1u;
    }
    state->healthy_run = 0u;
  } else if (state->paused) {
    state->healthy_run += 1u;
    if (state->healthy_run >= config->resume_after) state->paused = 0u;
  }

  if (state->paused) {
    flags |= FLAG_PAUSED;
  } else {
    /* Temperatures from the CVD inverse are always finite here; the status can only be ok. */
    (void)dp_diff_update_f32(&state->estimator, t1, t2);
    float gas = 0.0f;
    if (dp_recon_update_f32(&state->reconstruction, t1, t2, &gas) == DP_STATUS_OK &&
        state->taus_valid) {
      out->gas = gas;
      flags |= FLAG_GAS_VALID;
    }
  }

  state->tick += 1u;
  if (state->tick % config->solve_every == 0u) {
    flags |= FLAG_SOLVED;
    if (dp_diff_solve_f32(&state->estimator, &out->result) == DP_STATUS_OK &&
        dp_recon_set_time_constants_f32(&state->reconstruction, out->result.tau1,
                                        out->result.tau2) == DP_STATUS_OK) {
      state->taus_valid = 1u;
    }
  }
  if (state->taus_valid) flags |= FLAG_TAUS_VALID;
  out->tick = state->tick - 1u;
  out->flags = flags;
  out->t1 = t1;
  out->t2 = t2;
}

/* ---- text output: hexadecimal float bits, exact and identical on every target ------- */

typedef struct text_buffer {
  char data[512];
  uint32_t used;
} text_buffer;

static void flush(text_buffer *buffer) {
  if (buffer->used > 0u) platform_write(PLATFORM_STDOUT, buffer->data, buffer->used);
  buffer->used = 0u;
}

static void put_char(text_buffer *buffer, char c) {
  if (buffer->used == sizeof buffer->data) flush(buffer);
  buffer->data[buffer->used++] = c;
}

static void put_hex(text_buffer *buffer, uint32_t value, int digits) {
  static const char hex[] = "0123456789abcdef";
  for (int shift = 4 * (digits - 1); shift >= 0; shift -= 4) {
    put_char(buffer, hex[(value >> shift) & 0xFu]);
  }
}

static void put_dec(text_buffer *buffer, uint32_t value) {
  char digits[10];
  int n = 0;
  do {
    digits[n++] = (char)('0' + value % 10u);
    value /= 10u;
  } while (value != 0u);
  while (n > 0) put_char(buffer, digits[--n]);
}

static void put_float(text_buffer *buffer, float value) {
  uint32_t bits;
  memcpy(&bits, &value, sizeof bits);
  put_char(buffer, ' ');
  put_hex(buffer, bits, 8);
}

static void put_text(int stream, const char *text) {
  platform_write(stream, text, (uint32_t)strlen(text));
}

/* Static, not on the stack: the stack high-water mark then measures the control path. */
static firmware_state g_state;
static text_buffer g_out;

static void emit(text_buffer *buffer, const tick_output *out) {
  /* T <tick> <flags> <t1> <t2> <gas> [<gas at tick - lag>: the SVF loop] */
  put_char(buffer, 'T');
  put_char(buffer, ' ');
  put_dec(buffer, out->tick);
  put_char(buffer, ' ');
  put_hex(buffer, out->flags, 2);
  put_float(buffer, out->t1);
  put_float(buffer, out->t2);
  put_float(buffer, out->gas);
  if (g_state.config.estimator == ESTIMATOR_SVF) put_float(buffer, out->gas_lagged);
  put_char(buffer, '\n');
  if ((out->flags & FLAG_SOLVED) && g_state.config.estimator == ESTIMATOR_SVF) {
    /* R <tick> <status> <published> <tau1a> <tau1b> <tau2a> <tau2b> <exponent> <ratio> */
    put_char(buffer, 'R');
    put_char(buffer, ' ');
    put_dec(buffer, out->tick);
    put_char(buffer, ' ');
    put_dec(buffer, (uint32_t)out->robust.status);
    put_char(buffer, ' ');
    put_dec(buffer, (uint32_t)out->published);
    put_float(buffer, out->robust.tau1[0]);
    put_float(buffer, out->robust.tau1[1]);
    put_float(buffer, out->robust.tau2[0]);
    put_float(buffer, out->robust.tau2[1]);
    put_float(buffer, out->robust.exponent);
    put_float(buffer, out->robust.eigenvalue_ratio);
    put_char(buffer, '\n');
  } else if (out->flags & FLAG_SOLVED) {
    /* S <tick> <status> <beta> <b1> <b2> <tau1> <tau2> <eigenvalue ratio> */
    put_char(buffer, 'S');
    put_char(buffer, ' ');
    put_dec(buffer, out->tick);
    put_char(buffer, ' ');
    put_dec(buffer, (uint32_t)out->result.status);
    put_float(buffer, out->result.beta);
    put_float(buffer, out->result.b1);
    put_float(buffer, out->result.b2);
    put_float(buffer, out->result.tau1);
    put_float(buffer, out->result.tau2);
    put_float(buffer, out->result.eigenvalue_ratio);
    put_char(buffer, '\n');
  }
}


int firmware_run(const char *path) {
  if (path == NULL) {
    put_text(PLATFORM_STDERR, "error: no input file given\n");
    return 2;
  }
  const int handle = platform_open_input(path);
  if (handle < 0) {
    put_text(PLATFORM_STDERR, "error: cannot open the input file\n");
    return 2;
  }
  uint8_t header[FIRMWARE_HEADER_BYTES];
  firmware_config config;
  uint8_t extra[FIRMWARE_HEADER2_EXTRA_BYTES];
  if (platform_read(handle, header, FIRMWARE_HEADER_BYTES) != (int32_t)FIRMWARE_HEADER_BYTES ||
      firmware_parse_header(header, &config) != 0 ||
      (config.version == FIRMWARE_VERSION_ROBUST &&
       (platform_read(handle, extra, FIRMWARE_HEADER2_EXTRA_BYTES) !=
            (int32_t)FIRMWARE_HEADER2_EXTRA_BYTES ||
        firmware_parse_header2(extra, &config) != 0))) {
    platform_close(handle);
    put_text(PLATFORM_STDERR, "error: input header is not a version-1 or -2 DPFW block\n");
    return 2;
  }
  const uint32_t words = config.version == FIRMWARE_VERSION_ROBUST ? 3u : 2u;
  if (firmware_init(&g_state, &config) != DP_STATUS_OK) {
    platform_close(handle);
    put_text(PLATFORM_STDERR, "error: invalid calibration (estimator or reconstruction)\n");
    return 2;
  }
  /* Counts arrive in chunks, as from an ADC DMA buffer. */
  uint8_t chunk[64 * 12];
  uint32_t done = 0u;
  while (done < config.ticks) {
    uint32_t want = config.ticks - done;
    if (want > 64u) want = 64u;
    if (platform_read(handle, chunk, want * 4u * words) != (int32_t)(want * 4u * words)) {
      platform_close(handle);
      flush(&g_out);
      put_text(PLATFORM_STDERR, "error: input ends before the announced number of ticks\n");
      return 2;
    }
    for (uint32_t i = 0; i < want; ++i) {
      tick_output out;
      const uint8_t *row = chunk + 4u * words * i;
      const float flow = words == 3u ? read_f32(row + 8u) : 0.0f;
      firmware_tick_flow(&g_state, read_u32(row), read_u32(row + 4u), flow, &out);
      emit(&g_out, &out);
    }
    done += want;
  }
  platform_close(handle);
  flush(&g_out);
  return 0;
}
