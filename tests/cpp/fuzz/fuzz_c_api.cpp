// libFuzzer target over the C API (dualprobe.h): arbitrary configurations and sample
// streams, including NaN, Inf, huge and denormal values, chain breaks, resets and retunes.
// Besides crashes and sanitizer reports it fails on a status that lies:
//   - an ok estimate must be finite and feasible (beta > 0, 0 < b1, b2 < 1, tau > 0);
//   - a refused (non-finite) sample must leave the estimator bit for bit untouched;
//   - an ok reconstruction must be finite.
// Input layout: 8 configuration bytes, then 5-byte operations (opcode + 4 payload bytes).
// Most opcodes advance a simulated first-order sensor pair so that random inputs still reach
// well-excited, solvable states.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "dualprobe/dualprobe.h"

namespace {

const float kNan = std::nanf("");
const float kInf = INFINITY;
const float kIntervals[8] = {0.01f, 0.1f, 1.0f, 1e-30f, 1e30f, 0.0f, -1.0f, kNan};
const float kSigmas[8] = {0.02f, 1e-3f, 1.0f, 0.0f, 1e30f, kNan, -1.0f, 1e-30f};
const float kForgetting[8] = {1.0f, 0.9995f, 0.99f, 0.5f, 0.0f, 1.5f, kNan, 1e-30f};
const float kTaus[8] = {1.248f, 2.895f, 0.02f, 100.0f, 1e-30f, 1e30f, -3.0f, kInf};

// Evidence that random inputs reach solvable states (printed when the run ends).
unsigned long g_solves = 0;
unsigned long g_ok_solves = 0;
__attribute__((destructor)) void report_solves() {
  std::fprintf(stderr, "fuzz_c_api: %lu solves, %lu ok\n", g_solves, g_ok_solves);
}

[[noreturn]] void lie(const char* what) {
  std::fprintf(stderr, "status lie: %s\n", what);
  std::abort();
}

float float_bits(const uint8_t* p) {
  float value;
  std::memcpy(&value, p, sizeof value);
  return value;
}

void check_result(const dp_diff_result_f32& r, dp_status returned) {
  if (returned != r.status) lie("solve return value differs from result.status");
  ++g_solves;
  if (r.status != DP_STATUS_OK) return;
  ++g_ok_solves;
  const bool finite = std::isfinite(r.beta) && std::isfinite(r.b1) && std::isfinite(r.b2) &&
                      std::isfinite(r.tau1) && std::isfinite(r.tau2);
  if (!finite) lie("ok estimate with a non-finite value");
  if (!(r.beta > 0.0f && r.b1 > 0.0f && r.b1 < 1.0f && r.b2 > 0.0f && r.b2 < 1.0f)) {
    lie("ok estimate outside the feasible set");
  }
  if (!(r.tau1 > 0.0f && r.tau2 > 0.0f)) lie("ok estimate with a non-positive time constant");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 8) return 0;
  const dp_diff_config_f32 config = {kIntervals[data[0] & 7], static_cast<dp_method>(data[1] % 4),
                                     kSigmas[data[2] & 7], kSigmas[(data[2] >> 3) & 7],
                                     kForgetting[data[3] & 7]};
  dp_diff_instance_f32 estimator;
  dp_diff_init_f32(&estimator, &config);
  const dp_recon_config_f32 recon_config = {kIntervals[data[4] & 7], kTaus[(data[4] >> 3) & 7],
                                            kTaus[data[5] & 7], static_cast<dp_source>(data[5] >> 6),
                                            (data[6] & 1) ? 0.05f : 0.0f};
  dp_recon_instance_f32 reconstruction;
  dp_recon_init_f32(&reconstruction, &recon_config);

  // Simulated pair: first-order sensors (taus from the configuration byte) behind a gas
  // level that the payloads move.
  const float a1 = 0.99f, a2 = 0.996f;
  float gas = 200.0f + static_cast<float>(data[7]);
  float t1 = gas, t2 = gas;
  float block1[16], block2[16], block_gas[16];

  for (size_t i = 8; i + 5 <= size; i += 5) {
    const uint8_t op = data[i];
    const uint8_t* p = data + i + 1;
    float s1 = t1, s2 = t2;
    switch (op % 10) {
      case 0: case 1: case 2: case 3: {  // physical step, payload = gas change and noise
        int16_t step;
        std::memcpy(&step, p, sizeof step);
        gas += static_cast<float>(step) * 0.01f;
        t1 = a1 * t1 + (1.0f - a1) * gas;
        t2 = a2 * t2 + (1.0f - a2) * gas;
        s1 = t1 + static_cast<float>(static_cast<int8_t>(p[2])) * 1e-3f;
        s2 = t2 + static_cast<float>(static_cast<int8_t>(p[3])) * 1e-3f;
        break;
      }
      case 4: s1 = float_bits(p); break;  // raw bits on sensor 1: NaN, Inf, huge, denormal
      case 5: s2 = float_bits(p); break;
      case 6: {
        dp_diff_result_f32 r;
        check_result(r, dp_diff_solve_f32(&estimator, &r));
        if (r.status == DP_STATUS_OK && (p[0] & 1)) {
          dp_recon_set_time_constants_f32(&reconstruction, r.tau1, r.tau2);
        }
        continue;
      }
      case 7:
        if (p[0] & 1) dp_diff_break_chain_f32(&estimator);
        if (p[0] & 2) dp_diff_reset_f32(&estimator);
        if (p[0] & 4) dp_recon_reset_f32(&reconstruction);
        if (p[0] & 8) dp_recon_set_time_constants_f32(&reconstruction, float_bits(p), kTaus[p[1] & 7]);
        continue;
      case 8: {  // a block of physical samples through both block functions
        const uint32_t n = p[0] % 17;
        for (uint32_t k = 0; k < n; ++k) {
          t1 = a1 * t1 + (1.0f - a1) * gas;
          t2 = a2 * t2 + (1.0f - a2) * gas;
          block1[k] = t1;
          block2[k] = k == (p[1] & 15u) && (p[2] & 1) ? kNan : t2;
        }
        dp_diff_update_block_f32(&estimator, block1, block2, n);
        dp_recon_block_f32(&reconstruction, block1, block2, block_gas, n);
        continue;
      }
      default: s1 = float_bits(p) * 1e-20f; s2 = -s1; break;  // tiny and denormal values
    }
    float before[6], after[6];
    dp_diff_scatter_f32(&estimator, before);
    const float rows_before = dp_diff_rows_f32(&estimator);
    const dp_status status = dp_diff_update_f32(&estimator, s1, s2);
    const bool finite = std::isfinite(s1) && std::isfinite(s2);
    if (finite != (status == DP_STATUS_OK)) lie("update status does not match the sample");
    if (!finite) {
      dp_diff_scatter_f32(&estimator, after);
      const float rows_after = dp_diff_rows_f32(&estimator);
      if (std::memcmp(before, after, sizeof before) != 0 ||
          std::memcmp(&rows_before, &rows_after, sizeof rows_before) != 0) {
        lie("refused sample changed the state");
      }
    }
    float out = 0.0f;
    const dp_status recon = dp_recon_update_f32(&reconstruction, s1, s2, &out);
    if (recon == DP_STATUS_OK && !std::isfinite(out)) lie("ok reconstruction that is not finite");
    if (recon == DP_STATUS_NON_FINITE_INPUT && finite) lie("finite sample refused as non-finite");
  }
  dp_diff_result_f32 r;
  check_result(r, dp_diff_solve_f32(&estimator, &r));
  return 0;
}
