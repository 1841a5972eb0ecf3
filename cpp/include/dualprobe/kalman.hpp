// Causal reconstruction of the gas temperature: a Kalman filter on the state-space model of the
// sensor pair, with generalised-likelihood-ratio (GLR) detection of gas steps. Port of the
// specification in the docstring of python/dualprobe/reference/kalman.py (sections 1-4), to
// fixed memory: no heap, fixed-size Eigen types, noexcept, Status codes.
//
// State x = [g, (g'), sensor 1 stages, sensor 2 stages] (n = 1 or 2 gas states + 2..4 stages,
// n <= MaxStates). Gas: random walk (rw) or integrated random walk (irw) of intensity q; each
// sensor a chain of first-order stages of unit gain; y_i = last stage of sensor i + white noise.
// Hysteresis: stage j uses its cooling time constant while its input is below its state (mode
// from the state at the start of the interval; 2^stages precomputed models <= MaxModes).
//
// Per sample: exact prediction with the precomputed (Phi_m, q Qunit_m + Qfloor), time-varying
// gain, Joseph-form covariance update (computed as a symmetric product, so P stays exactly
// symmetric), then the GLR over the last `window` intervals: per candidate the effect of a unit
// jump at the start / end of its interval on the filtered state (2 x n), the accumulated
// a (2) and C (2 x 2, symmetric); a jump is applied when the best constrained statistic exceeds
// chi2_2.isf(false_alarm / window) = -2 ln(false_alarm / window).
//
// Fixed lag (MaxLag > 0, config lag L): the gas at t_{k-L} given the samples up to t_k, for a
// caller that can wait L samples (a logger, a diagnosis) -- near the offline smoother's accuracy
// for an L of a fraction of the sensors' time constants. The state is augmented only by what the
// mean and variance of the lagged gas need: per lagged instant its mean, variance and cross
// covariance with x (a ring of L entries, 2 + n scalars each; no L x L block). Predict pushes the
// filtered gas and ages the cross covariances (C <- C Phi^T); update applies the Kalman gain
// C H^T S^-1 (as the GLR does to its candidates). Without jump detection only: a GLR jump's
// effect on each lagged instant is not tracked (it would take window x lag more effects), and
// shifting the lagged instants by the current gas's correction was measured to double-count
// (a drive cycle's lagged RMSE 0.89 K with jumps against 0.44 K without). A caller wanting both
// runs a second, jump-free instance for the lagged output (the C API does).
//
// Configuration (discretisation, floors, threshold) runs in double for both scalar types, once;
// the per-sample recursion runs in Scalar. The filter works on the samples minus an offset (the
// first sample pair's mean) so that a float state holds kelvins around zero, not around 300:
// the model is invariant to a common offset (unit static gain, no absolute level anywhere).
//
// Float: det C / trace(C)^2 is only resolved to ~1e-7 in single precision, so the guard that
// decides whether the jump's position within its interval is resolved is 1e-5 there (1e-12 in
// double, as in the reference); below it the better single position (start or end) is used.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <type_traits>

#include "dualprobe/kalman_discretise.hpp"
#include "dualprobe/status.hpp"

namespace dualprobe {

enum class GasModel : int { random_walk = 0, integrated_random_walk = 1 };

namespace kalman_detail {
constexpr double kFloorRel = 1e-8;  // model-error variance per stage per sample / sigma^2
constexpr double kFloorDyn = 1.0;   // share of a first-order stage's within-interval variance
constexpr double kSpreadScale = 100.0;  // initial spread: 100 (|y1 - y2| + s1 + s2 + 1 K)

template <typename Scalar>
constexpr Scalar glr_singular() noexcept {
  // det C / trace(C)^2 below this: the jump's position in its interval is not resolved.
  return std::is_same<Scalar, float>::value ? Scalar(1e-5) : Scalar(1e-12);
}
}  // namespace kalman_detail

template <typename Scalar>
struct KalmanConfig {
  Scalar sample_interval{1};
  GasModel gas{GasModel::random_walk};
  int order1{1};  // stages of sensor 1 (1 or 2); the first order1 entries of taus1 are used
  int order2{1};
  std::array<Scalar, 2> taus1{{Scalar(1), Scalar(1)}};  // heating (or only) time constants, s
  std::array<Scalar, 2> taus2{{Scalar(1), Scalar(1)}};
  std::array<Scalar, 2> taus1_cool{{Scalar(0), Scalar(0)}};  // 0: same as heating
  std::array<Scalar, 2> taus2_cool{{Scalar(0), Scalar(0)}};
  Scalar sigma1{Scalar(0.1)};  // white-noise standard deviation of each sensor, K (> 0)
  Scalar sigma2{Scalar(0.1)};
  Scalar intensity{0};  // q >= 0: K^2/s (rw) or K^2/s^3 (irw)
  bool detect_jumps{true};
  int window{64};                   // GLR candidates kept (1 .. MaxWindow)
  Scalar false_alarm{Scalar(1e-6)};  // probability per sample of a spurious jump, (0, 1)
  int lag{0};  // fixed-lag output: 0 (the filtered gas) .. MaxLag samples
};

template <typename Scalar>
struct KalmanJump {
  std::uint32_t detected_at{0};  // sample index at which the jump was declared
  std::uint32_t interval{0};     // the jump happened between samples interval-1 and interval
  Scalar size{0};                // K
  Scalar fraction{0};            // position within the interval, 0 = start, 1 = end
};

template <typename Scalar, int MaxStates = 6, int MaxModes = 1, int MaxWindow = 64,
          int MaxLag = 0>
class KalmanReconstructor {
 public:
  static_assert(std::is_floating_point<Scalar>::value, "Scalar must be float or double");
  static_assert(MaxStates >= 3 && MaxStates <= 6,
                "state size: 1-2 gas states + 1-2 stages per sensor (3..6)");
  static_assert(MaxModes >= 1 && MaxModes <= 16 && (MaxModes & (MaxModes - 1)) == 0,
                "hysteresis modes: a power of two, at most 2^4");
  static_assert(MaxWindow >= 1 && MaxWindow <= 4096, "GLR window capacity");
  static_assert(MaxLag >= 0 && MaxLag <= 4096, "fixed-lag capacity");

  static constexpr int max_states = MaxStates;
  static constexpr int max_modes = MaxModes;
  static constexpr int max_window = MaxWindow;
  static constexpr int max_lag = MaxLag;

  using Config = KalmanConfig<Scalar>;
  using Jump = KalmanJump<Scalar>;
  using Vector = Eigen::Matrix<Scalar, MaxStates, 1>;
  using Matrix = Eigen::Matrix<Scalar, MaxStates, MaxStates>;

  KalmanReconstructor() noexcept { clear_state(); }

  // Validates and discretises; on any invalid value returns invalid_argument and leaves the
  // reconstructor as it was. On success the filter restarts at the next sample.
  Status configure(const Config& config) noexcept {
    Layout layout;
    if (!make_layout(config, &layout)) return Status::invalid_argument;
    if (!discretise_all(config, layout)) return Status::invalid_argument;
    layout_ = layout;
    set_parameters(config);
    configured_ = true;
    reset();
    return Status::ok;
  }

  // New time constants, noise levels or intensity for a running filter (e.g. after the online
  // estimator re-solved): keeps the state and covariance. The gas model and the sensor orders
  // must stay; otherwise (or if invalid, or not configured yet) invalid_argument, untouched.
  // The jump candidates are dropped: their evidence was weighed with the old model (kept, a
  // wrong model's systematic innovations can pass for a jump of any size).
  Status retune(const Config& config) noexcept {
    Layout layout;
    if (!configured_ || !make_layout(config, &layout) || config.gas != config_.gas ||
        config.order1 != config_.order1 || config.order2 != config_.order2) {
      return Status::invalid_argument;
    }
    if (!discretise_all(config, layout)) return Status::invalid_argument;
    count_ = 0;
    first_ = 0;
    layout_ = layout;
    set_parameters(config);
    return Status::ok;
  }

  // Flow schedule (design.md 1.5): the transition Phi and process noise of the interval that
  // ends at the next update(), for dynamics that change from sample to sample (the caller
  // discretises tau(t), e.g. per stage in closed form). Keeps the state, the covariance and the
  // GLR candidates: every candidate's effect is propagated with the Phi of each interval it
  // lives through, so its statistic is that of the time-varying model (unlike retune(), whose
  // candidates were weighed with another model). Single-mode models only; unused entries
  // beyond states() must be those of configure() (identity in Phi, zero in the noise).
  // Not configured, hysteretic, or a non-finite entry: invalid_argument, untouched.
  Status set_model(const Matrix& phi, const Matrix& process) noexcept {
    if (!configured_ || layout_.modes != 1) return Status::invalid_argument;
    if (!phi.allFinite() || !process.allFinite()) return Status::invalid_argument;
    phi_[0] = phi;
    process_[0] = process;
    return Status::ok;
  }

  // Back to the state before the first sample (the configuration stays).
  void reset() noexcept { clear_state(); }

  // Consumes the sample pair T1(k), T2(k); on ok writes the filtered gas temperature at t_k to
  // *gas (if given). Non-finite samples are refused (non_finite_input) with the state
  // untouched; not_ready before configure(); infeasible if the filter left the finite range
  // (it then restarts at the next sample) -- an ok status always comes with a finite output.
  Status update(Scalar t1, Scalar t2, Scalar* gas = nullptr) noexcept {
    if (!configured_) return Status::not_ready;
    if (!std::isfinite(t1) || !std::isfinite(t2)) return Status::non_finite_input;
    jumped_ = false;
    int mode = 0;
    const bool first = !started_;
    if (first) {
      initialise(t1, t2);
    } else {
      mode = predict();
    }
    const Scalar y1 = t1 - offset_;
    const Scalar y2 = t2 - offset_;
    const int o1 = layout_.output1;
    const int o2 = layout_.output2;
    // S = H P H^T + R and its inverse (2 x 2, closed form).
    const Scalar s00 = p_(o1, o1) + r1_;
    const Scalar s01 = p_(o1, o2);
    const Scalar s11 = p_(o2, o2) + r2_;
    const Scalar det = s00 * s11 - s01 * s01;
    if (!(det > Scalar(0)) || !std::isfinite(det)) return diverged();
    const Scalar inv_det = Scalar(1) / det;
    const Scalar i00 = s11 * inv_det;
    const Scalar i01 = -s01 * inv_det;
    const Scalar i11 = s00 * inv_det;
    const Scalar e0 = y1 - x_[o1];
    const Scalar e1 = y2 - x_[o2];
    const Scalar u0 = i00 * e0 + i01 * e1;  // S^-1 e
    const Scalar u1 = i01 * e0 + i11 * e1;
    Gain gain;
    gain.col(0) = p_.col(o1) * i00 + p_.col(o2) * i01;
    gain.col(1) = p_.col(o1) * i01 + p_.col(o2) * i11;
    if constexpr (MaxLag > 0) lagged_update(gain, e0, e1, i00, i01, i11);
    x_ += gain.col(0) * e0 + gain.col(1) * e1;
    // Joseph form P = (I - K H) P (I - K H)^T + K R K^T, symmetric by construction.
    Matrix b = Matrix::Identity();
    b.col(o1) -= gain.col(0);
    b.col(o2) -= gain.col(1);
    const Matrix bp = b.lazyProduct(p_);
    for (int i = 0; i < MaxStates; ++i) {
      for (int j = 0; j <= i; ++j) {
        const Scalar v = bp.row(i).dot(b.row(j)) + r1_ * gain(i, 0) * gain(j, 0) +
                         r2_ * gain(i, 1) * gain(j, 1);
        p_(i, j) = v;
        p_(j, i) = v;
      }
    }
    log_likelihood_ -= Scalar(0.5) * (e0 * u0 + e1 * u1 + std::log(kFourPiSquared * det));
    if (detect_ && !first) {
      glr_update(phi_[mode], gain, u0, u1, i00, i01, i11);
    }
    started_ = true;
    ++samples_;  // a counter for the caller and the jump report only (wraps after 2^32)
    const Scalar out = x_[0] + offset_;
    if (!std::isfinite(out)) return diverged();
    if (gas != nullptr) *gas = out;
    return Status::ok;
  }

  // A sample instant without a usable measurement (e.g. a sensor fault): the prediction only,
  // so time stays aligned; the GLR candidates age but learn nothing. Writes the predicted gas.
  // not_ready before the first sample.
  Status skip(Scalar* gas = nullptr) noexcept {
    if (!configured_ || !started_) return Status::not_ready;
    jumped_ = false;
    const int mode = predict();
    if (detect_) {  // no measurement: the candidates only age (all but the one just added)
      int index = first_;
      for (int c = 0; c + 1 < count_; ++c) {
        propagate(candidates_[index], phi_[mode]);
        index = index + 1 == window_ ? 0 : index + 1;
      }
    }
    ++samples_;
    const Scalar out = x_[0] + offset_;
    if (!std::isfinite(out) || !std::isfinite(p_(0, 0))) return diverged();
    if (gas != nullptr) *gas = out;
    return Status::ok;
  }

  // n sample pairs; out[k] = filtered gas, NaN where the pair was refused (non-finite; the
  // instant is then skipped, so later samples stay on their time grid) or the filter restarted.
  // Returns the number of pairs without an ok update.
  std::size_t update_block(const Scalar* t1, const Scalar* t2, std::size_t n,
                           Scalar* out) noexcept {
    std::size_t refused = 0;
    const Scalar nan = std::numeric_limits<Scalar>::quiet_NaN();
    for (std::size_t k = 0; k < n; ++k) {
      Scalar gas = nan;
      Status status = update(t1[k], t2[k], &gas);
      if (status == Status::non_finite_input) {
        (void)skip();
        gas = nan;
      }
      if (status != Status::ok) {
        gas = nan;
        ++refused;
      }
      out[k] = gas;
    }
    return refused;
  }

  bool configured() const noexcept { return configured_; }
  const Config& config() const noexcept { return config_; }
  int states() const noexcept { return layout_.n; }
  int modes() const noexcept { return layout_.modes; }
  std::uint32_t samples() const noexcept { return samples_; }
  Scalar gas() const noexcept { return x_[0] + offset_; }
  Scalar gas_variance() const noexcept { return p_(0, 0); }
  int lag() const noexcept { return lag_; }
  // The fixed-lag gas at t_{k-lag} given the samples up to t_k (k: the last update or skip) and
  // its variance (>= 0); false (outputs untouched) until lag instants have passed since the
  // start. lag 0: the filtered gas.
  bool lagged(Scalar* gas, Scalar* variance) const noexcept {
    if (!started_) return false;
    Scalar mean = x_[0];
    Scalar var = p_(0, 0);
    if constexpr (MaxLag > 0) {
      if (lag_ > 0) {
        if (lag_count_ < lag_) return false;
        const LagEntry& oldest = lagged_[lag_head_ + 1 == lag_ ? 0 : lag_head_ + 1];
        mean = oldest.mean;
        var = oldest.variance;
      }
    }
    if (gas != nullptr) *gas = mean + offset_;
    if (variance != nullptr) *variance = var > Scalar(0) ? var : Scalar(0);
    return true;
  }
  // State with the offset restored (levels in K; an irw slope in K/s), unused entries zero.
  Vector state() const noexcept {
    Vector out = x_;
    for (int i = 0; i < layout_.n; ++i) {
      if (!(layout_.gas_states == 2 && i == 1)) out[i] += offset_;
    }
    return out;
  }
  const Matrix& covariance() const noexcept { return p_; }
  Scalar log_likelihood() const noexcept { return log_likelihood_; }
  Scalar threshold() const noexcept { return threshold_; }
  int candidates() const noexcept { return count_; }
  bool jump_detected() const noexcept { return jumped_; }  // in the last update
  const Jump& last_jump() const noexcept { return last_jump_; }
  std::uint32_t jump_count() const noexcept { return jump_count_; }
  // The precomputed model of hysteresis mode m (0 = every stage heating).
  const Matrix& transition(int mode) const noexcept { return phi_[mode]; }
  const Matrix& process_noise(int mode) const noexcept { return process_[mode]; }

 private:
  using Gain = Eigen::Matrix<Scalar, MaxStates, 2>;
  // Row r: effect on the filtered state of a unit gas jump at the start (r = 0) or the end
  // (r = 1) of the candidate's interval. Row-major, unaligned: exactly 2 n scalars.
  using Effect = Eigen::Matrix<Scalar, 2, MaxStates, Eigen::RowMajor | Eigen::DontAlign>;
  using DoubleMatrix = Eigen::Matrix<double, MaxStates, MaxStates>;

  static constexpr Scalar kFourPiSquared = Scalar(39.47841760435743);  // (2 pi)^2

  struct Candidate {
    Effect effect;
    Scalar a0;
    Scalar a1;
    Scalar c00;
    Scalar c01;
    Scalar c11;
  };

  // One lagged instant: its gas mean and variance and the cross covariance Cov(g, x).
  struct LagEntry {
    Scalar mean;
    Scalar variance;
    Scalar cross[MaxStates];
  };

  struct Layout {
    int n{0};
    int gas_states{1};
    int stages{0};
    int modes{1};
    int output1{0};
    int output2{0};
    int noise_index{0};
    std::array<int, 4> stage_input{{0, 0, 0, 0}};
    std::array<int, 4> stage_state{{0, 0, 0, 0}};
    std::array<int, 4> stage_sensor{{0, 0, 0, 0}};
    std::array<double, 4> tau_heat{{1, 1, 1, 1}};
    std::array<double, 4> tau_cool{{1, 1, 1, 1}};
  };

  struct GlrFit {
    Scalar stat{0};
    Scalar alpha{0};
    Scalar beta{0};
    Scalar w00{0};
    Scalar w01{0};
    Scalar w11{0};
  };

  static bool positive_finite(Scalar v) noexcept { return v > Scalar(0) && std::isfinite(v); }

  static bool make_layout(const Config& c, Layout* out) noexcept {
    if (!positive_finite(c.sample_interval)) return false;
    if (c.gas != GasModel::random_walk && c.gas != GasModel::integrated_random_walk) return false;
    if (c.order1 < 1 || c.order1 > 2 || c.order2 < 1 || c.order2 > 2) return false;
    if (!positive_finite(c.sigma1) || !positive_finite(c.sigma2)) return false;
    if (!(c.intensity >= Scalar(0)) || !std::isfinite(c.intensity)) return false;
    if (c.window < 1 || c.window > MaxWindow) return false;
    if (c.lag < 0 || c.lag > MaxLag || (c.lag > 0 && c.detect_jumps)) return false;
    if (!(c.false_alarm > Scalar(0)) || !(c.false_alarm < Scalar(1))) return false;
    Layout l;
    l.gas_states = c.gas == GasModel::integrated_random_walk ? 2 : 1;
    l.noise_index = l.gas_states - 1;
    l.stages = c.order1 + c.order2;
    l.n = l.gas_states + l.stages;
    if (l.n > MaxStates) return false;
    bool hysteretic = false;
    int index = l.gas_states;
    int j = 0;
    for (int sensor = 0; sensor < 2; ++sensor) {
      const int order = sensor == 0 ? c.order1 : c.order2;
      const auto& heat = sensor == 0 ? c.taus1 : c.taus2;
      const auto& cool = sensor == 0 ? c.taus1_cool : c.taus2_cool;
      int source = 0;
      for (int s = 0; s < order; ++s, ++j) {
        if (!positive_finite(heat[s])) return false;
        if (!(cool[s] >= Scalar(0)) || !std::isfinite(cool[s])) return false;
        l.stage_input[j] = source;
        l.stage_state[j] = index;
        l.stage_sensor[j] = sensor;
        l.tau_heat[j] = double(heat[s]);
        l.tau_cool[j] = cool[s] > Scalar(0) ? double(cool[s]) : double(heat[s]);
        hysteretic = hysteretic || l.tau_cool[j] != l.tau_heat[j];
        source = index;
        ++index;
      }
      (sensor == 0 ? l.output1 : l.output2) = source;
    }
    l.modes = hysteretic ? (1 << l.stages) : 1;
    if (l.modes > MaxModes) return false;
    *out = l;
    return true;
  }

  static DoubleMatrix continuous(const Layout& l, int mode) noexcept {
    DoubleMatrix f = DoubleMatrix::Zero();
    if (l.gas_states == 2) f(0, 1) = 1.0;
    for (int j = 0; j < l.stages; ++j) {
      const double tau = ((mode >> j) & 1) ? l.tau_cool[j] : l.tau_heat[j];
      f(l.stage_state[j], l.stage_input[j]) += 1.0 / tau;
      f(l.stage_state[j], l.stage_state[j]) -= 1.0 / tau;
    }
    return f;
  }

  // Discretises every mode into phi_/process_ (Phi_m and q Qunit_m + Qfloor) if every entry is
  // finite in Scalar; else returns false with the members untouched. One mode (the ECU's
  // case): computed once into locals. Several: a checking pass, then the same arithmetic again
  // to store (the members are the only storage big enough for all modes).
  bool discretise_all(const Config& c, const Layout& l) noexcept {
    if (MaxModes == 1 || l.modes == 1) {
      DoubleMatrix phi;
      DoubleMatrix process;
      if (!discretise_mode(c, l, 0, &phi, &process)) return false;
      phi_[0] = phi.template cast<Scalar>();
      process_[0] = process.template cast<Scalar>();
      return true;
    }
    DoubleMatrix phi;
    DoubleMatrix process;
    for (int m = 0; m < l.modes; ++m) {
      if (!discretise_mode(c, l, m, &phi, &process)) return false;
    }
    for (int m = 0; m < l.modes; ++m) {
      discretise_mode(c, l, m, &phi, &process);
      phi_[m] = phi.template cast<Scalar>();
      process_[m] = process.template cast<Scalar>();
    }
    return true;
  }

  // Phi_m and q Qunit_m + Qfloor in double; false unless every entry is finite in Scalar.
  static bool discretise_mode(const Config& c, const Layout& l, int mode, DoubleMatrix* phi,
                              DoubleMatrix* process) noexcept {
    const double ts = double(c.sample_interval);
    const double q = double(c.intensity);
    const auto d = kalman_detail::discretise<MaxStates>(continuous(l, mode), l.noise_index, ts);
    // The floor: the variance of one gas increment (Qunit[0, 0], the same in every mode: the
    // gas does not see the stages; rw Ts, irw Ts^3/3, here to rounding) and the heating
    // time constants.
    const double gas_step = q * (l.gas_states == 1 ? ts : ts * ts * ts / 3.0);
    *phi = d.phi;
    *process = q * d.q_unit;
    for (int j = 0; j < l.stages; ++j) {
      const double sigma = double(l.stage_sensor[j] == 0 ? c.sigma1 : c.sigma2);
      const double ratio = ts / l.tau_heat[j];
      (*process)(l.stage_state[j], l.stage_state[j]) +=
          kalman_detail::kFloorRel * sigma * sigma +
          kalman_detail::kFloorDyn * gas_step * ratio * ratio / 12.0;
    }
    const double limit = double(std::numeric_limits<Scalar>::max());
    return phi->allFinite() && process->allFinite() && phi->cwiseAbs().maxCoeff() <= limit &&
           process->cwiseAbs().maxCoeff() <= limit;
  }

  void set_parameters(const Config& c) noexcept {
    if (c.lag != lag_) lag_count_ = 0;  // another lag: the ring restarts
    lag_ = c.lag;
    config_ = c;
    r1_ = c.sigma1 * c.sigma1;
    r2_ = c.sigma2 * c.sigma2;
    detect_ = c.detect_jumps;
    window_ = c.window;
    threshold_ = Scalar(-2.0 * std::log(double(c.false_alarm) / double(c.window)));
    double tau_min = layout_.tau_heat[0];
    for (int j = 1; j < layout_.stages; ++j) {
      tau_min = layout_.tau_heat[j] < tau_min ? layout_.tau_heat[j] : tau_min;
    }
    tau_min_ = Scalar(tau_min);
  }

  void clear_state() noexcept {
    x_.setZero();
    p_.setZero();
    offset_ = Scalar(0);
    log_likelihood_ = Scalar(0);
    samples_ = 0;
    started_ = false;
    first_ = 0;
    count_ = 0;
    jumped_ = false;
    last_jump_ = Jump{};
    jump_count_ = 0;
    lag_head_ = 0;
    lag_count_ = 0;
  }

  Status diverged() noexcept {
    clear_state();
    return Status::infeasible;
  }

  // Section 4 defaults (reference: default_initial_state), relative to the offset.
  void initialise(Scalar t1, Scalar t2) noexcept {
    offset_ = Scalar(0.5) * (t1 + t2);
    const Scalar y[2] = {t1 - offset_, t2 - offset_};
    const Scalar sigma[2] = {config_.sigma1, config_.sigma2};
    const Scalar spread =
        Scalar(kalman_detail::kSpreadScale) * (std::abs(t1 - t2) + sigma[0] + sigma[1] + Scalar(1));
    const Scalar spread2 = spread * spread;
    x_.setZero();
    p_.setZero();
    p_(0, 0) = spread2;
    if (layout_.gas_states == 2) {
      const Scalar slope = spread / tau_min_;
      p_(1, 1) = slope * slope;
    }
    for (int j = 0; j < layout_.stages; ++j) {
      const int s = layout_.stage_state[j];
      x_[s] = y[layout_.stage_sensor[j]];
      p_(s, s) = spread2;
    }
    p_(layout_.output1, layout_.output1) = sigma[0] * sigma[0];
    p_(layout_.output2, layout_.output2) = sigma[1] * sigma[1];
  }

  int mode_of(const Vector& x) const noexcept {
    int mode = 0;
    for (int j = 0; j < layout_.stages; ++j) {
      mode |= int(x[layout_.stage_input[j]] < x[layout_.stage_state[j]]) << j;
    }
    return mode;
  }

  // x <- Phi_m x, P <- Phi_m P Phi_m^T + process_m (symmetric), and the new GLR candidate for
  // the interval just elapsed (the oldest dropped when the window is full). The older
  // candidates' M <- M Phi_m^T is left to the caller (fused with the GLR update, one pass over
  // the window). Returns the mode m.
  int predict() noexcept {
    const int m = MaxModes > 1 && layout_.modes > 1 ? mode_of(x_) : 0;
    const Matrix& phi = phi_[m];
    if constexpr (MaxLag > 0) {
      if (lag_ > 0) lagged_predict(phi);
    }
    const Vector x = x_;
    x_ = phi.lazyProduct(x);
    const Matrix left = phi.lazyProduct(p_);
    for (int i = 0; i < MaxStates; ++i) {
      for (int j = 0; j <= i; ++j) {
        const Scalar v = left.row(i).dot(phi.row(j)) + process_[m](i, j);
        p_(i, j) = v;
        p_(j, i) = v;
      }
    }
    if (!detect_) return m;
    if (count_ == window_) {  // drop the oldest
      first_ = first_ + 1 == window_ ? 0 : first_ + 1;
      --count_;
    }
    int slot = first_ + count_;
    slot = slot >= window_ ? slot - window_ : slot;
    Candidate& fresh = candidates_[slot];
    fresh.effect.row(0) = phi.col(0).transpose();  // jump at the start: Phi e_0
    fresh.effect.row(1).setZero();                 // jump at the end: e_0
    fresh.effect(1, 0) = Scalar(1);
    fresh.a0 = fresh.a1 = Scalar(0);
    fresh.c00 = fresh.c01 = fresh.c11 = Scalar(0);
    ++count_;
    return m;
  }

  // Pushes the filtered gas of the interval's start as the newest lagged instant (the oldest
  // dropped when the ring is full), then ages every cross covariance: C <- C Phi^T.
  void lagged_predict(const Matrix& phi) noexcept {
    if constexpr (MaxLag == 0) {  // no code (and no zero-size array access) without a lag
      (void)phi;
    } else {
      // Filling: slots 0, 1, ... in order; full: the oldest slot (after the newest) is reused.
      if (lag_count_ < lag_) {
        lag_head_ = lag_count_++;
      } else {
        lag_head_ = lag_head_ + 1 == lag_ ? 0 : lag_head_ + 1;
      }
      LagEntry& fresh = lagged_[lag_head_];
      fresh.mean = x_[0];
      fresh.variance = p_(0, 0);
      for (int i = 0; i < MaxStates; ++i) fresh.cross[i] = p_(0, i);
      for (int a = 0; a < lag_count_; ++a) {
        Scalar* c = lagged_[a].cross;
        Scalar aged[MaxStates];
#pragma GCC unroll 6
        for (int i = 0; i < MaxStates; ++i) {
          Scalar s = c[0] * phi(i, 0);
#pragma GCC unroll 6
          for (int j = 1; j < MaxStates; ++j) s += c[j] * phi(i, j);
          aged[i] = s;
        }
#pragma GCC unroll 6
        for (int i = 0; i < MaxStates; ++i) c[i] = aged[i];
      }
    }
  }

  // The measurement update of every lagged instant, with rho = C H^T: mean += rho S^-1 e,
  // variance -= rho S^-1 rho^T, C <- C - rho K^T (K from the prior covariance, as for x).
  void lagged_update(const Gain& gain, Scalar e0, Scalar e1, Scalar i00, Scalar i01,
                     Scalar i11) noexcept {
    if constexpr (MaxLag == 0) {
      (void)gain, (void)e0, (void)e1, (void)i00, (void)i01, (void)i11;
    } else {
      const int o1 = layout_.output1;
      const int o2 = layout_.output2;
      for (int a = 0; a < lag_count_; ++a) {
        LagEntry& entry = lagged_[a];
        const Scalar r0 = entry.cross[o1];
        const Scalar r1 = entry.cross[o2];
        const Scalar g0 = r0 * i00 + r1 * i01;
        const Scalar g1 = r0 * i01 + r1 * i11;
        entry.mean += g0 * e0 + g1 * e1;
        entry.variance -= g0 * r0 + g1 * r1;
#pragma GCC unroll 6
        for (int i = 0; i < MaxStates; ++i) {
          entry.cross[i] -= r0 * gain(i, 0) + r1 * gain(i, 1);
        }
      }
    }
  }

  // M <- M Phi^T for one candidate (rows of M are contiguous: row-major storage).
  static void propagate(Candidate& cand, const Matrix& phi) noexcept {
    Scalar* row0 = cand.effect.data();
    Scalar* row1 = row0 + MaxStates;
    Scalar new0[MaxStates];
    Scalar new1[MaxStates];
#pragma GCC unroll 6
    for (int i = 0; i < MaxStates; ++i) {
      Scalar s0 = row0[0] * phi(i, 0);
      Scalar s1 = row1[0] * phi(i, 0);
#pragma GCC unroll 6
      for (int j = 1; j < MaxStates; ++j) {
        s0 += row0[j] * phi(i, j);
        s1 += row1[j] * phi(i, j);
      }
      new0[i] = s0;
      new1[i] = s1;
    }
#pragma GCC unroll 6
    for (int i = 0; i < MaxStates; ++i) {
      row0[i] = new0[i];
      row1[i] = new1[i];
    }
  }

  // Best (alpha, beta) with the jump inside its interval (alpha beta >= 0), its statistic and
  // the inverse information W (reference: _glr_statistics).
  static GlrFit fit(const Candidate& c) noexcept {
    GlrFit f;
    const Scalar stat0 = c.c00 > Scalar(0) ? c.a0 * c.a0 / c.c00 : Scalar(0);
    const Scalar stat1 = c.c11 > Scalar(0) ? c.a1 * c.a1 / c.c11 : Scalar(0);
    if (stat0 >= stat1) {  // start preferred on a tie
      f.stat = stat0;
      if (c.c00 > Scalar(0)) {
        f.alpha = c.a0 / c.c00;
        f.w00 = Scalar(1) / c.c00;
      }
    } else {
      f.stat = stat1;
      f.beta = c.a1 / c.c11;
      f.w11 = Scalar(1) / c.c11;
    }
    const Scalar det = c.c00 * c.c11 - c.c01 * c.c01;
    const Scalar trace = c.c00 + c.c11;
    if (det > kalman_detail::glr_singular<Scalar>() * trace * trace) {
      const Scalar inv_det = Scalar(1) / det;
      const Scalar alpha = (c.c11 * c.a0 - c.c01 * c.a1) * inv_det;
      const Scalar beta = (c.c00 * c.a1 - c.c01 * c.a0) * inv_det;
      if (alpha * beta >= Scalar(0)) {
        f.stat = c.a0 * alpha + c.a1 * beta;
        f.alpha = alpha;
        f.beta = beta;
        f.w00 = c.c11 * inv_det;
        f.w01 = -c.c01 * inv_det;
        f.w11 = c.c00 * inv_det;
      }
    }
    return f;
  }

  // The per-candidate statistic only (the same arithmetic as fit(), fewer stores).
  static Scalar statistic(const Candidate& c) noexcept {
    const Scalar stat0 = c.c00 > Scalar(0) ? c.a0 * c.a0 / c.c00 : Scalar(0);
    const Scalar stat1 = c.c11 > Scalar(0) ? c.a1 * c.a1 / c.c11 : Scalar(0);
    Scalar stat = stat0 >= stat1 ? stat0 : stat1;
    const Scalar det = c.c00 * c.c11 - c.c01 * c.c01;
    const Scalar trace = c.c00 + c.c11;
    if (det > kalman_detail::glr_singular<Scalar>() * trace * trace) {
      const Scalar inv_det = Scalar(1) / det;
      const Scalar alpha = (c.c11 * c.a0 - c.c01 * c.a1) * inv_det;
      const Scalar beta = (c.c00 * c.a1 - c.c01 * c.a0) * inv_det;
      if (alpha * beta >= Scalar(0)) stat = c.a0 * alpha + c.a1 * beta;
    }
    return stat;
  }

  // Section 4, GLR: for every candidate (oldest first; all but the newest first aged by
  // M <- M Phi^T) a += rho S^-1 e, C += rho S^-1 rho^T, M <- M - rho K^T with rho = M H^T;
  // then the best statistic, and the jump if it exceeds the threshold.
  void glr_update(const Matrix& phi, const Gain& gain, Scalar u0, Scalar u1, Scalar i00,
                  Scalar i01, Scalar i11) noexcept {
    const int o1 = layout_.output1;
    const int o2 = layout_.output2;
    Scalar k0[MaxStates];
    Scalar k1[MaxStates];
#pragma GCC unroll 6
    for (int i = 0; i < MaxStates; ++i) {
      k0[i] = gain(i, 0);
      k1[i] = gain(i, 1);
    }
    Scalar best_stat = Scalar(-1);
    int best = -1;
    int best_age = 0;
    int index = first_;
    for (int c = 0; c < count_; ++c) {
      Candidate& cand = candidates_[index];
      if (c + 1 < count_) propagate(cand, phi);
      Scalar* row0 = cand.effect.data();
      Scalar* row1 = row0 + MaxStates;
      // rho = M H^T: the innovations a unit (alpha, beta) adds.
      const Scalar r00 = row0[o1];
      const Scalar r01 = row0[o2];
      const Scalar r10 = row1[o1];
      const Scalar r11 = row1[o2];
      cand.a0 += r00 * u0 + r01 * u1;
      cand.a1 += r10 * u0 + r11 * u1;
      const Scalar v00 = r00 * i00 + r01 * i01;  // rho S^-1
      const Scalar v01 = r00 * i01 + r01 * i11;
      const Scalar v10 = r10 * i00 + r11 * i01;
      const Scalar v11 = r10 * i01 + r11 * i11;
      cand.c00 += v00 * r00 + v01 * r01;
      cand.c01 += v00 * r10 + v01 * r11;
      cand.c11 += v10 * r10 + v11 * r11;
#pragma GCC unroll 6
      for (int i = 0; i < MaxStates; ++i) {
        row0[i] -= r00 * k0[i] + r01 * k1[i];
        row1[i] -= r10 * k0[i] + r11 * k1[i];
      }
      const Scalar stat = statistic(cand);
      if (stat > best_stat) {  // the first (oldest) of equal maxima
        best_stat = stat;
        best = index;
        best_age = count_ - 1 - c;
      }
      index = index + 1 == window_ ? 0 : index + 1;
    }
    if (best < 0 || !(best_stat > threshold_)) return;
    const Candidate& cand = candidates_[best];
    const GlrFit f = fit(cand);
    const Effect& e = cand.effect;
    x_ += f.alpha * e.row(0).transpose() + f.beta * e.row(1).transpose();
    // P += M^T W M (symmetric)
    for (int i = 0; i < MaxStates; ++i) {
      const Scalar w0 = f.w00 * e(0, i) + f.w01 * e(1, i);
      const Scalar w1 = f.w01 * e(0, i) + f.w11 * e(1, i);
      for (int j = 0; j <= i; ++j) {
        const Scalar v = p_(i, j) + w0 * e(0, j) + w1 * e(1, j);
        p_(i, j) = v;
        p_(j, i) = v;
      }
    }
    const Scalar size = f.alpha + f.beta;
    last_jump_.detected_at = samples_;
    last_jump_.interval = samples_ - std::uint32_t(best_age);
    last_jump_.size = size;
    last_jump_.fraction = size != Scalar(0) ? f.beta / size : Scalar(0);
    ++jump_count_;
    jumped_ = true;
    count_ = 0;
    first_ = 0;
  }

  Config config_{};
  Layout layout_{};
  std::array<Matrix, MaxModes> phi_{};
  std::array<Matrix, MaxModes> process_{};
  Vector x_{};
  Matrix p_{};
  Scalar offset_{0};
  Scalar r1_{1};
  Scalar r2_{1};
  Scalar threshold_{0};
  Scalar tau_min_{1};
  Scalar log_likelihood_{0};
  std::uint32_t samples_{0};
  std::uint32_t jump_count_{0};
  Jump last_jump_{};
  int window_{1};
  int first_{0};
  int count_{0};
  bool detect_{false};
  bool configured_{false};
  bool started_{false};
  bool jumped_{false};
  std::array<Candidate, MaxWindow> candidates_{};
  std::array<LagEntry, MaxLag> lagged_{};
  int lag_{0};
  int lag_head_{0};   // ring index of the newest lagged instant (age 1)
  int lag_count_{0};  // lagged instants held, <= lag_
};

// The configurations an ECU instantiates: a first-order pair with a random-walk gas (3
// states), and the largest model (two second-order sensors, integrated random walk).
template <typename Scalar, int MaxWindow = 64>
using KalmanFirstOrder = KalmanReconstructor<Scalar, 3, 1, MaxWindow>;
template <typename Scalar, int MaxWindow = 64>
using KalmanFull = KalmanReconstructor<Scalar, 6, 1, MaxWindow>;

// Memory is fixed by the template arguments: the GLR window dominates (2 n + 5 scalars per
// candidate), then one transition and one process-noise matrix per mode.
static_assert(sizeof(KalmanFirstOrder<float>) <= 3584, "first-order float Kalman grew");
static_assert(sizeof(KalmanFull<double>) <= 12288, "full double Kalman grew");

}  // namespace dualprobe
