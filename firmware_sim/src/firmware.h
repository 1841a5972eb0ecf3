/* The ECU firmware loop: two Pt-100 channels read as ADC counts every tick, converted to
 * temperature (Callendar-Van Dusen inverse), checked for open/short faults, fed to the
 * dual-sensor estimator every tick, solved every `solve_every` ticks, and the gas temperature
 * reconstructed every tick with the latest good time constants.
 *
 * Fault handling: a faulted channel flags the tick, pauses the estimator and the
 * reconstruction, and breaks the estimator's difference chain (no row spans the gap). The
 * channel must read healthy for `resume_after` consecutive ticks before both resume; the
 * accumulated scatter (and so the estimate) survives the fault. */
#ifndef FIRMWARE_FIRMWARE_H
#define FIRMWARE_FIRMWARE_H

#include <stdint.h>

#include "adc.h"
#include "dualprobe/dualprobe.h"

/* Calibration block of the input stream, little-endian (see README): version 1 is 56 bytes
 * and two uint32 counts per tick; version 2 appends 52 bytes (the robust estimator and the
 * Kalman reconstruction, its fixed lag last) and carries a third word per tick, the exhaust
 * flow (float bits). */
#define FIRMWARE_MAGIC 0x57465044ul /* "DPFW" */
#define FIRMWARE_VERSION 1u
#define FIRMWARE_VERSION_ROBUST 2u
#define FIRMWARE_HEADER_BYTES 56u
#define FIRMWARE_HEADER2_EXTRA_BYTES 52u

typedef enum firmware_estimator {
  ESTIMATOR_DIFFERENCE = 0, /* the paper's difference estimator + exact inverse (version 1) */
  ESTIMATOR_SVF = 1         /* SVF cross-relation estimator + causal Kalman reconstruction */
} firmware_estimator;

typedef struct firmware_config {
  uint32_t ticks;
  float sample_interval; /* s, the tick period */
  dp_method method;
  float sigma1, sigma2; /* K */
  float forgetting;
  uint32_t solve_every;  /* ticks between solves, >= 1 */
  uint32_t resume_after; /* healthy ticks needed after a fault */
  dp_source source;
  float lowpass_tau;               /* s, 0 = none */
  float initial_tau1, initial_tau2; /* s; 0 = no reconstruction before the first good solve */
  /* Version 2 only (version 1: estimator = ESTIMATOR_DIFFERENCE, no flow word). */
  uint32_t version;
  firmware_estimator estimator;
  uint32_t order;             /* 1 or 2: SVF order and stages per sensor in the Kalman */
  float filter_time_constant; /* s */
  float quantisation;         /* K, the ADC step near the operating point (noise floor) */
  float flow_ref;             /* flow unit; 0 = no flow channel (tracking with forgetting) */
  float exponent;             /* initial m (order 2 with flow) */
  float max_eigenvalue_ratio; /* identifiability gate of a solve */
  float intensity;            /* Kalman gas random-walk intensity, K^2/s */
  uint32_t window;            /* GLR candidates, 0 = no jump detection */
  float false_alarm;          /* GLR false-alarm probability per sample */
  float tau_min, tau_max;     /* s: plausible time constants; a solve outside is not published */
  uint32_t lag;               /* ticks of the fixed-lag output, 0 (none) .. DP_KALMAN_MAX_LAG */
} firmware_config;

/* Tick flags. */
#define FLAG_CH1_OPEN 0x01u
#define FLAG_CH1_SHORT 0x02u
#define FLAG_CH2_OPEN 0x04u
#define FLAG_CH2_SHORT 0x08u
#define FLAG_PAUSED 0x10u    /* estimator not updated this tick */
#define FLAG_GAS_VALID 0x20u /* gas holds a reconstruction */
#define FLAG_TAUS_VALID 0x40u
#define FLAG_SOLVED 0x80u /* a solve ran this tick; see tick_output.result */

typedef struct firmware_state {
  firmware_config config;
  dp_diff_instance_f32 estimator;
  dp_recon_instance_f32 reconstruction;
  dp_svf_instance_f32 svf;
  dp_kalman_instance_f32 kalman;
  dp_svf_result_f32 good; /* the last published SVF result */
  uint32_t tick;
  uint32_t healthy_run; /* consecutive healthy ticks */
  uint8_t paused;
  uint8_t taus_valid;
} firmware_state;

typedef struct tick_output {
  uint32_t tick;
  uint32_t flags;
  float t1, t2;  /* C; NaN for a faulted channel */
  float gas;     /* C; NaN unless FLAG_GAS_VALID */
  float gas_lagged; /* C: the gas of tick - lag (fixed lag, version 2); NaN when not ready */
  dp_diff_result_f32 result; /* valid with FLAG_SOLVED (difference estimator) */
  dp_svf_result_f32 robust;  /* valid with FLAG_SOLVED (SVF estimator) */
  uint8_t published;         /* the SVF solve passed every check and retuned the Kalman */
} tick_output;

/* Parses and validates the 56-byte calibration block; returns 0 or a negative error. A
 * version-2 block returns 0 with config->version = 2: the caller then reads the 52 further
 * bytes with firmware_parse_header2. */
int firmware_parse_header(const uint8_t header[FIRMWARE_HEADER_BYTES], firmware_config *config);
int firmware_parse_header2(const uint8_t extra[FIRMWARE_HEADER2_EXTRA_BYTES],
                           firmware_config *config);
/* Returns DP_STATUS_OK, or the init status of the estimator / reconstruction. */
dp_status firmware_init(firmware_state *state, const firmware_config *config);
void firmware_tick(firmware_state *state, uint32_t counts1, uint32_t counts2, tick_output *out);
/* The version-2 tick: flow is this tick's exhaust flow (ignored without a flow channel). */
void firmware_tick_flow(firmware_state *state, uint32_t counts1, uint32_t counts2, float flow,
                        tick_output *out);

/* Shared by both loops (firmware.c): ADC -> CVD -> open/short flags; t NaN when faulted. */
uint32_t firmware_read_channels(uint32_t counts1, uint32_t counts2, float *t1, float *t2);
float firmware_nan(void);
/* The SVF + Kalman loop (firmware_robust.c). */
dp_status firmware_robust_init(firmware_state *state);
void firmware_robust_tick(firmware_state *state, uint32_t counts1, uint32_t counts2, float flow,
                          tick_output *out);

/* Runs the whole input stream at `path`, one text line per tick on stdout (README: output
 * format); returns the process exit status (0 ok, 2 bad input). */
int firmware_run(const char *path);

#endif
