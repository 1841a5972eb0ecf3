/*
 * dualprobe C API: the fixed-memory dual-sensor estimator and the gas-temperature
 * reconstruction for firmware, in the CMSIS-DSP style (caller-owned instance structs,
 * init / reset / update / solve / reconstruct functions, float only).
 *
 * Valid C99 and C++. No heap, no exceptions, no RTTI, no static initialisers: an instance is
 * plain storage whose size is fixed at compile time; it may live in .bss, on the stack or in a
 * struct. Every function is re-entrant on distinct instances. Pointers must be non-null unless
 * said otherwise (a null instance or output pointer gives DP_STATUS_INVALID_ARGUMENT).
 *
 * Typical ECU use (see firmware_sim/src/firmware.c):
 *   dp_diff_instance_f32 est;  dp_recon_instance_f32 rec;
 *   dp_diff_init_f32(&est, &diff_config);              // once
 *   every tick:  dp_diff_update_f32(&est, t1, t2);      // O(1), a few dozen instructions
 *                dp_recon_update_f32(&rec, t1, t2, &gas);
 *   every N ticks: dp_diff_solve_f32(&est, &result);    // a few thousand instructions
 *                  if ok: dp_recon_set_time_constants_f32(&rec, result.tau1, result.tau2);
 *   after a sensor fault: dp_diff_break_chain_f32(&est) so no difference spans the gap.
 */
#ifndef DUALPROBE_DUALPROBE_H
#define DUALPROBE_DUALPROBE_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Mirrors dualprobe::Status one for one. */
typedef enum dp_status {
  DP_STATUS_OK = 0,
  DP_STATUS_INSUFFICIENT_EXCITATION = 1, /* too few rows, or signals that do not move enough */
  DP_STATUS_INFEASIBLE = 2,              /* a solution that is not physical (b outside (0,1), ...) */
  DP_STATUS_NON_FINITE_INPUT = 3,        /* NaN/Inf sample refused (see each update) */
  DP_STATUS_INVALID_ARGUMENT = 4,        /* bad configuration or null pointer, state untouched */
  DP_STATUS_NOT_READY = 5                /* no result yet (e.g. first sample of a reconstruction) */
} dp_status;

/* Mirrors dualprobe::Method. */
typedef enum dp_method { DP_METHOD_LS = 0, DP_METHOD_TLS = 1, DP_METHOD_GTLS = 2 } dp_method;

/* Mirrors dualprobe::ReconstructionSource. */
typedef enum dp_source {
  DP_SOURCE_SENSOR1 = 0,
  DP_SOURCE_SENSOR2 = 1,
  DP_SOURCE_WEIGHTED = 2 /* w = tau2^2 / (tau1^2 + tau2^2) on sensor 1 */
} dp_source;

/* ---- Difference-equation estimator (design 1.2, paper eqs. 10-12) ------------------------ */

typedef struct dp_diff_config_f32 {
  float sample_interval; /* Ts in seconds, > 0 */
  dp_method method;
  float sigma1;     /* white-noise std of sensor 1 in K, > 0 for GTLS */
  float sigma2;     /* white-noise std of sensor 2 in K, > 0 for GTLS */
  float forgetting; /* lambda in (0, 1]; 1 = no forgetting */
} dp_diff_config_f32;

typedef struct dp_diff_result_f32 {
  dp_status status; /* the other fields are meaningful only when DP_STATUS_OK */
  float beta;
  float b1;
  float b2;
  float tau1; /* s */
  float tau2; /* s */
  float eigenvalue_ratio; /* smallest / second-smallest eigenvalue, near 0 = well identified */
} dp_diff_result_f32;

/* Storage for one estimator; the layout is private to the implementation (a checked
 * static_assert ties it to dualprobe::DifferenceEstimator<float>). */
#define DP_DIFF_INSTANCE_BYTES 64
typedef struct dp_diff_instance_f32 {
  union {
    uint32_t words[DP_DIFF_INSTANCE_BYTES / 4];
    float align_float;
    void *align_pointer;
  } storage;
} dp_diff_instance_f32;

/* Configures and clears. On DP_STATUS_INVALID_ARGUMENT the instance is still initialised (so
 * later calls are defined) but unconfigured: solve then reports DP_STATUS_INVALID_ARGUMENT. */
dp_status dp_diff_init_f32(dp_diff_instance_f32 *instance, const dp_diff_config_f32 *config);

/* Clears the accumulated data, keeps the configuration. */
void dp_diff_reset_f32(dp_diff_instance_f32 *instance);

/* Forgets the previous sample but keeps the accumulated data: call when a sensor was faulted,
 * so the next update starts a new chain of differences instead of spanning the gap. */
void dp_diff_break_chain_f32(dp_diff_instance_f32 *instance);

/* One sample pair (K). O(1). A non-finite sample returns DP_STATUS_NON_FINITE_INPUT, keeps the
 * accumulated data and breaks the chain of differences (as dp_diff_break_chain_f32): the next
 * sample starts a new chain, so no difference spans the refused sample. */
dp_status dp_diff_update_f32(dp_diff_instance_f32 *instance, float t1, float t2);

/* block_size sample pairs, exactly as block_size calls of dp_diff_update_f32; returns the
 * first non-ok status (a refused sample breaks the chain, the others are accumulated). */
dp_status dp_diff_update_block_f32(dp_diff_instance_f32 *instance, const float *t1,
                                   const float *t2, uint32_t block_size);

/* Solves the accumulated scatter; the instance is not modified. Returns result->status. */
dp_status dp_diff_solve_f32(const dp_diff_instance_f32 *instance, dp_diff_result_f32 *result);

/* Diagnostics: effective number of rows (sum of lambda^age), and the packed upper triangle of
 * the 3x3 scatter [S00 S01 S02 S11 S12 S22] of z = [dT1(k), dT12(k-1), dT2(k)]. */
float dp_diff_rows_f32(const dp_diff_instance_f32 *instance);
dp_status dp_diff_scatter_f32(const dp_diff_instance_f32 *instance, float packed[6]);

/* ---- Exact-inverse reconstruction (design 1.3) ------------------------------------------- */

typedef struct dp_recon_config_f32 {
  float sample_interval; /* Ts in seconds, > 0 */
  float tau1;            /* s, > 0 */
  float tau2;            /* s, > 0 */
  dp_source source;
  float lowpass_tau; /* s; 0 = no low-pass stage */
} dp_recon_config_f32;

#define DP_RECON_INSTANCE_BYTES 80
typedef struct dp_recon_instance_f32 {
  union {
    uint32_t words[DP_RECON_INSTANCE_BYTES / 4];
    float align_float;
    void *align_pointer;
  } storage;
} dp_recon_instance_f32;

/* Configures and clears. Same contract as dp_diff_init_f32 on a bad configuration (update
 * then returns DP_STATUS_INVALID_ARGUMENT until a valid init). */
dp_status dp_recon_init_f32(dp_recon_instance_f32 *instance, const dp_recon_config_f32 *config);

/* Clears the sample history (the next update only primes), keeps the configuration. */
void dp_recon_reset_f32(dp_recon_instance_f32 *instance);

/* Retunes to new time constants (e.g. after each successful solve) without losing the
 * previous sample, so the output continues without a gap. Invalid taus: the instance is left
 * as it was and DP_STATUS_INVALID_ARGUMENT is returned. */
dp_status dp_recon_set_time_constants_f32(dp_recon_instance_f32 *instance, float tau1,
                                          float tau2);

/* Consumes T1(k), T2(k); on DP_STATUS_OK writes the gas temperature over [k-1, k) to *gas
 * (always finite). The first sample after init/reset only primes and returns
 * DP_STATUS_NOT_READY. A non-finite sample returns DP_STATUS_NON_FINITE_INPUT, state and *gas
 * untouched. A value that overflows float (absurd samples or time constants) returns
 * DP_STATUS_INFEASIBLE, *gas untouched, the sample kept as the previous one. */
dp_status dp_recon_update_f32(dp_recon_instance_f32 *instance, float t1, float t2, float *gas);

/* block_size calls of dp_recon_update_f32; gas[i] is NaN where no value was formed. Returns
 * the first status other than ok / not_ready, else ok. */
dp_status dp_recon_block_f32(dp_recon_instance_f32 *instance, const float *t1, const float *t2,
                             float *gas, uint32_t block_size);

/* Name of a status ("ok", "infeasible", ...); "unknown" for values outside the enum. */
const char *dp_status_string(dp_status status);

/* ---- Noise-robust SVF cross-relation estimator (design 1.4, 1.5; issue 13) ----------------
 * dualprobe::SvfEstimator<float, order, unit, ..., SolveScalar = float, Basis> behind a C
 * instance: every tick dp_svf_update_f32 (O(1), float), every N ticks dp_svf_solve_f32 (a
 * float GTLS solve, no double arithmetic). With flow_ref > 0 the static relation is scheduled
 * by the flow channel: psi = sum_j a_j (flow/flow_ref)^m_j over the fixed basis
 * m_j = 0.25, 0.5, 0.75 (square roots only), and the solve fits tau = tau_ref
 * (flow/flow_ref)^-m to it (tau_ref exactly: psi(flow_ref) normalises; m by least squares of
 * log psi on log flow over the flows seen). Without a flow channel (flow_ref = 0) the
 * estimator tracks the time constants with forgetting (their ratio constant in the window).
 * Order 2 with a flow channel: the second-derivative column needs phi = 1/psi per sample; it
 * uses (flow/flow_ref)^-m with the exponent of the last ok solve (initially `exponent`). */

typedef struct dp_svf_config_f32 {
  float sample_interval;      /* Ts, s, > 0 */
  float filter_time_constant; /* tf, s, > 0 (about half the fast time constant) */
  uint32_t order;             /* 1 or 2 */
  float sigma1, sigma2;       /* white-noise std, K, >= 0 (GTLS; 0 and 0: TLS limit) */
  float quantisation;         /* ADC step in K, >= 0: noise floor sigma^2 += step^2 / 12 */
  float forgetting;           /* (0, 1]; 1 = none */
  float flow_ref;             /* > 0: a flow channel (same unit); 0: no flow */
  float exponent;             /* order 2 with flow: initial m for phi, in [0, 2] */
  float max_eigenvalue_ratio; /* (0, 1]: solves less identifiable than this are refused */
} dp_svf_config_f32;

typedef struct dp_svf_result_f32 {
  dp_status status; /* the other fields are meaningful only when DP_STATUS_OK */
  uint32_t order;
  float tau1[2]; /* s, at flow_ref, largest first (order 1: [1] = 0) */
  float tau2[2];
  float exponent;         /* m of tau = tau_ref (flow/flow_ref)^-m; 0 without flow */
  float eigenvalue_ratio; /* smallest / second generalised eigenvalue (identifiability) */
  float rows;             /* forgetting-weighted number of rows */
} dp_svf_result_f32;

/* The core's fixed-size Eigen members may need 16-byte alignment (SIMD on the host); the
 * implementation checks it with a static_assert. */
#if defined(__GNUC__) || defined(__clang__)
#define DP_ALIGN16 __attribute__((aligned(16)))
#else
#define DP_ALIGN16
#endif

#define DP_SVF_INSTANCE_BYTES 1536
typedef struct DP_ALIGN16 dp_svf_instance_f32 {
  union {
    uint32_t words[DP_SVF_INSTANCE_BYTES / 4];
    float align_float;
    void *align_pointer;
    double align_double;
  } storage;
} dp_svf_instance_f32;

/* Configures and clears; a bad configuration returns DP_STATUS_INVALID_ARGUMENT and leaves an
 * unconfigured instance (update and solve then return DP_STATUS_INVALID_ARGUMENT). */
dp_status dp_svf_init_f32(dp_svf_instance_f32 *instance, const dp_svf_config_f32 *config);
void dp_svf_reset_f32(dp_svf_instance_f32 *instance);
/* One sample pair (K) and the flow of this sample (ignored without a flow channel). Non-finite
 * values: DP_STATUS_NON_FINITE_INPUT; flow <= 0: DP_STATUS_INVALID_ARGUMENT; either way the
 * state is untouched. */
dp_status dp_svf_update_f32(dp_svf_instance_f32 *instance, float t1, float t2, float flow);
/* A gap in the samples (a sensor fault): the filter cascades join the next sample to the last
 * one and the next ceil(25 tf / Ts) rows, while their transient decays, are not accumulated;
 * the accumulated data (and so the estimate) survive. */
void dp_svf_break_chain_f32(dp_svf_instance_f32 *instance);
/* Solves (instance unchanged but for the order-2 phi exponent after an ok solve; see above).
 * Never returns ok with a non-finite, non-positive or unidentifiable result. */
dp_status dp_svf_solve_f32(dp_svf_instance_f32 *instance, dp_svf_result_f32 *result);
/* psi = (flow/flow_ref)^m of a result (1 without flow or for a non-ok result). */
float dp_svf_schedule_f32(const dp_svf_instance_f32 *instance, const dp_svf_result_f32 *result,
                          float flow);

/* ---- Causal Kalman reconstruction with GLR jump detection (kalman.hpp; issue 13) -----------
 * Gas as a random walk of intensity q, each sensor a chain of 1 or 2 first-order stages whose
 * time constants are tau_ref / psi(k): psi is given per sample (the flow schedule; 1 without
 * flow). The transition of each interval is formed in float in closed form (one expf per
 * stage, expm1f for a second stage); its process noise by the midpoint rule. */

#define DP_KALMAN_MAX_WINDOW 8
/* Fixed-lag output (dp_kalman_lagged_f32): the gas at t_{k-lag} from the samples up to t_k,
 * near the offline smoother's accuracy for a lag of a tenth of the faster sensor's time
 * constant. 28 bytes of state per lag sample, inside the instance. */
#define DP_KALMAN_MAX_LAG 20

typedef struct dp_kalman_config_f32 {
  float sample_interval; /* Ts, s, > 0 */
  uint32_t order1, order2; /* stages per sensor, 1 or 2 */
  float taus1[2], taus2[2]; /* s at psi = 1 (order 1: [1] unused) */
  float sigma1, sigma2;   /* white-noise std, K, >= 0 */
  float quantisation;     /* ADC step in K, >= 0: sigma^2 += step^2 / 12; the sum must be > 0 */
  float intensity;        /* q, K^2/s, > 0 */
  uint32_t window;        /* GLR candidates, 0 (no jump detection) .. DP_KALMAN_MAX_WINDOW */
  float false_alarm;      /* (0, 1) per sample */
  uint32_t lag;           /* fixed-lag output, samples: 0 (none) .. DP_KALMAN_MAX_LAG */
} dp_kalman_config_f32;

#define DP_KALMAN_INSTANCE_BYTES 2400
typedef struct DP_ALIGN16 dp_kalman_instance_f32 {
  union {
    uint32_t words[DP_KALMAN_INSTANCE_BYTES / 4];
    float align_float;
    void *align_pointer;
    double align_double;
  } storage;
} dp_kalman_instance_f32;

dp_status dp_kalman_init_f32(dp_kalman_instance_f32 *instance, const dp_kalman_config_f32 *config);
/* Back to before the first sample (the configuration stays). */
void dp_kalman_reset_f32(dp_kalman_instance_f32 *instance);
/* New time constants at psi = 1 (e.g. after an ok solve), keeping the state; orders must stay.
 * Invalid: DP_STATUS_INVALID_ARGUMENT, untouched. */
dp_status dp_kalman_retune_f32(dp_kalman_instance_f32 *instance, const float taus1[2],
                               const float taus2[2]);
/* T1(k), T2(k) and psi(k) > 0; on ok the filtered gas at t_k in *gas. Non-finite input:
 * DP_STATUS_NON_FINITE_INPUT, psi <= 0: DP_STATUS_INVALID_ARGUMENT, state untouched. The
 * first sample after init/reset starts the filter and is ok. */
dp_status dp_kalman_update_f32(dp_kalman_instance_f32 *instance, float t1, float t2, float psi,
                               float *gas);
uint32_t dp_kalman_jumps_f32(const dp_kalman_instance_f32 *instance);
/* After an ok update at t_k: the gas at t_{k-lag} given the samples up to t_k in *gas and its
 * standard deviation in *std (K; either may be NULL). DP_STATUS_NOT_READY until lag samples
 * have passed since the start (or a reset), or with lag 0; nothing written then. */
dp_status dp_kalman_lagged_f32(const dp_kalman_instance_f32 *instance, float *gas, float *std);

#ifdef __cplusplus
} /* extern "C" */
#endif

#endif /* DUALPROBE_DUALPROBE_H */
