// Streaming state-variable-filter (SVF) cross-relation estimator (design.md 1.4, 1.5; issues 6
// and 7). The batch references and full specifications are python/dualprobe/reference/svf.py
// and (flow schedule) python/dualprobe/reference/svf_schedule.py.
//
// Eliminating the gas temperature, P1(s) T1 = g P2(s) T2 + o (unit static model: g = 1, o = 0).
// Both signals pass the same filter F(s) = 1/(1 + tf s)^(order+1) (svf_filter.hpp, exact FOH);
// the scaled derivatives x_j = (tf s)^j F T form the regression row z, and the relation
// theta . z = 0 is solved by generalised TLS with the noise covariance of z.
//   unit:   z = [x_1..x_n(T1), -x_1..x_n(T2), x_0(T2) - x_0(T1)]
//   affine: z = [x_1..x_n(T1), -x_1..x_n(T2), -x_0(T2), -x_0(T1)]   (constant projected out)
// theta, scatter() and noise_covariance() use this documented column order. The affine static
// pair is accumulated as d = x_0(T2) - x_0(T1) and s = -x_0(T1) and mapped back only in the
// solve precision: the two nearly collinear columns of a few hundred kelvin would otherwise
// carry their small difference only in the rounding of their float products (issue-6 100 Hz
// pair, float: fast pole 10-40 % off, against 0.03 % this way).
// Hysteresis (order 1): x_1 of each sensor is split into a heating and a cooling column, the
// derivative of the sensor being filtered (ZOH) with the weights h and 1 - h of a zero-lag
// direction classification that looks w samples ahead (a fixed-capacity delay line).
//
// Flow schedule (Basis = K >= 1, design.md 1.5): the time constants of both sensors follow one
// common factor, tau(t) = tau_ref phi(t), psi = 1/phi, and the static relation is scheduled by
// per-sample weights b_1(k)..b_K(k), psi = sum_j a_j b_j (K = 1: psi is the weight itself).
// Exact for first-order sensors: psi (T2 - T1) = tau1 T1' - tau2 T2'; for two-stage sensors
// whose stages both scale with phi: psi (Tg - T) = c T' + d (phi T')'. Columns (every F starts
// in steady state at its input's first value):
//   order 1, unit:   z = [x_1(T1), -x_1(T2), F(b_1 (T2 - T1)), ..., F(b_K (T2 - T1))]
//   order 2, unit:   z = [x_1(T1), y_1(T1), -x_1(T2), -y_1(T2), F(b_1 (T2 - T1)), ...]
//   affine (K = 1):  static pair [-F(psi T2), -F(psi T1)], offset regressor r = F(psi)
//   hysteresis (K = 1): split derivative columns as above, static column(s) scheduled.
// y_1(T) = tf s F(tf phi s T): a ZOH cascade driven on interval k by
// (phi(k) + phi(k+1))/2 (T(k+1) - T(k)) tf/Ts (trapezoidal mean of phi: second order like the
// FOH columns; phi(k) alone biased the sheath time constants by 0.1-0.5 % on a noise-free 10 Hz
// drive cycle, the mean <= 1.1e-5) and y_1 the derivative-map row 1 of its states; with
// phi == 1 it is x_2 exactly.
// theta (last entry -1): order 1 [tau1/tf, tau2/tf, -a_1/a_K, .., -1], order 2 [c1/tf, d1/tf^2,
// c2/tf, d2/tf^2, -a_1/a_K, .., -1] (time constants at psi = 1). For K > 1 the time constants
// are computed as if a_K were 1 (they are tau/a_K): the caller renormalises psi.
// Centring: the unit static column is F(b_j (u2 - u1)) + (T2(0) - T1(0)) F(b_j), u_i = T_i -
// T_i(0); the row is accumulated as [z_centred, r_1..r_K] with r_j = F(b_j) and solve() adds
// the offsets back exactly. Affine: the static pair is accumulated as d = F(psi (u2 - u1)) and
// s = -F(psi u1) (the offsets times r vanish in the projection), the row as [z, r].
// Noise: to first order in the variation of the weights over the filter memory, each column's
// noise is a per-row weight times the stationary noise of its unscheduled source column C0
// (derivative columns 1, split h / 1 - h, y_1 columns phi with source x_2, static columns b_j),
// so C[a][b] = C0[src a][src b] sum_rows w_a w_b, from the moments of
// omega(k) = [1, (h1, h2), (phi), b_1..b_K] (the entries the variant has; the first row of the
// hysteresis variant, which has no interval, counts as undecided, h = 1/2). C only enters the
// GTLS bias correction.
//
// update() is O(1) and allocation free: it advances the filter cascades and accumulates
//   * the scatter of the augmented row [z, e] (so sum z z^T, sum z e^T and sum e e^T in one
//     SymmetricScatter; e = 1 without a schedule, r_1..r_K or r with one), block-summed: a block
//     of 64 rows is summed alone and then added to the total with Kahan compensation, which
//     keeps float sums at the rounding of the rows themselves however long the record (plain
//     summation: up to 10x worse on 45000 rows);
//   * during the first (60 + 2m) tf/Ts rows, sum z b^T, sum e b^T and sum b b^T for the filter's
//     free responses b(k) = phi^k e_0: every start-up transient of the filtered columns lies in
//     their span and solve() projects it out (no warm-up samples are discarded);
//   * hysteresis and schedule: the moments of omega for the noise covariance.
// The signals are centred on their first samples (kept as offsets): the filter and the moments
// then work on temperature changes rather than on ~300 K absolute values.
//
// Moments (resampling): everything solve() reads is a fixed-length vector of double moments,
// moments() (MomentLayout: packed augmented scatter, transient cross sum z b^T and sum e b^T,
// packed transient Gram, packed omega moments, row count), plus the first samples T1(0), T2(0)
// kept outside it. Without forgetting every entry is a sum over rows, so moment vectors of
// disjoint stretches of rows add up: snapshots every L samples, differenced, give block
// moments, and solve(total - block) is the estimate without that block's rows (delete-a-block
// jackknife). Differences keep each entry to the rounding of the running totals: the transient
// moments of the rows after the first block, decayed to e^-(L Ts/tf) of its own, round away
// once L Ts/tf exceeds ~20, and the replicate without the first block then projects none.
// With forgetting the vector is a snapshot for solve() only (the transient moments carry their
// decay).
//
// solve() assembles the projected scatter, runs GTLS exactly as the reference does (scaling by
// diag(S)^-1/2, C regularised by 1e-12 max(trace, 1) I) in SolveScalar, double by default also
// for the float estimator: solve() runs rarely, and a float eigen-solve loses the small
// generalised eigenvalues next to the huge ones of high-SNR records (issue-6 100 Hz pair, affine:
// a float solve missed the 0.17 s pole by 5-10 % or found no relation at all; a double solve of
// the same float moments is within 0.2 %). It returns the polynomial coefficients, the time
// constants per sensor (largest first), heating/cooling time constants, gain ratio and
// offset, and the generalised eigenvalues (the identifiability measure). The hysteresis variant
// runs the last w rows, whose look-ahead windows are clipped by the end of the record, on a copy
// of the working state, so solve() stays const and matches the batch reference.
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <type_traits>

#include "dualprobe/scatter.hpp"
#include "dualprobe/status.hpp"
#include "dualprobe/svf_filter.hpp"

namespace dualprobe {

enum class StaticModel : int { unit = 0, affine = 1 };

template <typename Scalar>
struct SvfConfig {
  Scalar sample_interval{1};
  Scalar filter_time_constant{1};  // tf; the Python layer chooses it (tf = kappa tau_fast)
  Scalar sigma1{0};                // white-noise standard deviation of sensor 1 (0: TLS limit)
  Scalar sigma2{0};
  Scalar forgetting{1};  // 1 = none; 0.9999 forgets with a memory of about 10^4 samples
  // Hysteresis variant only: half window (samples) of each sensor's heating/cooling
  // classification (1 <= w <= MaxHalfWindow) and its dead zone in noise standard deviations.
  int direction_half_window1{1};
  int direction_half_window2{1};
  Scalar dead_zone{2};
};

template <typename Scalar, int Order, int P>
struct SvfResult {
  using Polynomial = Eigen::Matrix<Scalar, Order, 1>;
  Status status{Status::not_ready};
  // theta . z = 0 with theta's last entry -1 (column order in the file comment).
  Eigen::Matrix<Scalar, P, 1> theta{Eigen::Matrix<Scalar, P, 1>::Zero()};
  // P_i(s) = 1 + p_i1 s + ... + p_in s^n (seconds^j); hysteresis: the heating/cooling mean.
  Polynomial polynomial1{Polynomial::Zero()};
  Polynomial polynomial2{Polynomial::Zero()};
  // Roots of P_i as time constants, largest first; NaN where not real and positive.
  Polynomial time_constants1{Polynomial::Zero()};
  Polynomial time_constants2{Polynomial::Zero()};
  // Hysteresis variant only (else 0).
  Scalar tau_heat1{0};
  Scalar tau_cool1{0};
  Scalar tau_heat2{0};
  Scalar tau_cool2{0};
  // Affine static model only: g = gain1/gain2 and o in P1 T1 = g P2 T2 + o (unit: 1 and 0).
  Scalar gain_ratio{1};
  Scalar offset{0};
  // Generalised eigenvalues of S v = mu C v, ascending. With the right noise level the
  // smallest is ~1; a second one close to it means the relation is not identifiable (a pole
  // shared by both sensors, or no excitation).
  Eigen::Matrix<Scalar, P, 1> eigenvalues{Eigen::Matrix<Scalar, P, 1>::Zero()};
  Scalar eigenvalue_ratio{0};  // smallest / second smallest: near 0 well defined, near 1 not
  Scalar rows{0};              // (forgetting-weighted) number of rows
};

namespace svf_detail {

// Sum over a sliding window with bounded rounding drift: elements that were in the window at
// the last restart are subtracted from `stale` as they leave, new ones summed afresh; after one
// window length stale holds only rounding residue and the fresh sum replaces it. So the error
// never grows beyond one window's worth of roundings, however long the stream.
template <typename Scalar>
struct WindowSum {
  Scalar stale{0};
  Scalar fresh{0};
  int size{0};
  int since{0};

  bool full(int length) const noexcept { return size >= length; }
  void grow(Scalar x, int length) noexcept {
    fresh += x;
    if (++size == length) restart();
  }
  void slide(Scalar entering, Scalar leaving, int length) noexcept {
    fresh += entering;
    stale -= leaving;
    if (++since == length) restart();
  }
  void restart() noexcept {
    stale = fresh;
    fresh = Scalar(0);
    since = 0;
  }
  Scalar sum() const noexcept { return stale + fresh; }
};

}  // namespace svf_detail

// Scalar: the per-sample arithmetic and the stored state (float on the ECU). Order: 1 or 2.
// Static: unit or affine model. Hysteresis: heating/cooling split (order 1). MaxHalfWindow:
// capacity of the look-ahead delay line (direction windows beyond it are invalid_argument; 128
// covers tf/Ts up to 128, e.g. tf = 12.8 s at 10 Hz). SolveScalar: precision of solve().
// Basis: 0 = no flow schedule (update(t1, t2)); K >= 1 = static relation scheduled by K
// per-sample weights (update(t1, t2, weights, phi); K = 1 also update(t1, t2, psi)); the affine
// model and the hysteresis split take K = 1 only; K <= 8.
template <typename Scalar, int Order, StaticModel Static = StaticModel::unit,
          bool Hysteresis = false, int MaxHalfWindow = 128, typename SolveScalar = double,
          int Basis = 0>
class SvfEstimator {
 public:
  static_assert(std::is_floating_point<Scalar>::value, "Scalar must be float or double");
  static_assert(Order == 1 || Order == 2, "the SVF estimator supports order 1 and 2");
  static_assert(!Hysteresis || Order == 1, "the hysteresis split is defined for order 1 only");
  static_assert(MaxHalfWindow >= 1 && MaxHalfWindow <= 65536, "direction window capacity");
  static_assert(Basis >= 0 && Basis <= 8, "schedule basis: 0 (none) up to 8 weights");
  static_assert(Basis <= 1 || Static == StaticModel::unit,
                "the affine static model takes a single schedule psi (Basis 1)");
  static_assert(Basis <= 1 || !Hysteresis, "the hysteresis split takes a single schedule psi");

  static constexpr int order = Order;
  static constexpr int states = Order + 1;  // cascade length m
  static constexpr bool affine = Static == StaticModel::affine;
  static constexpr bool hysteresis = Hysteresis;
  static constexpr int schedule_basis = Basis;
  static constexpr bool scheduled = Basis > 0;
  // The unscheduled, unsplit layout: the noise model's source columns.
  static constexpr int unsplit_columns = 2 * Order + (affine ? 2 : 1);
  static constexpr int static_columns = affine ? 2 : (scheduled ? Basis : 1);
  static constexpr int dynamic_columns = Hysteresis ? 4 : 2 * Order;
  static constexpr int columns = dynamic_columns + static_columns;
  // Appended to z in the accumulated row: 1 (no schedule), r_1..r_K (unit) or r (affine).
  static constexpr int extras = scheduled ? Basis : 1;
  static constexpr int augmented_size = columns + extras;
  static constexpr int basis_size = states + (affine ? 1 : 0);
  // omega = [1, (h1, h2), (phi), b_1..b_K, (p1, p2)]; without a schedule [has interval, h1, h2,
  // p1, p2] or [1]. p_i: sensor i's h on the previous row (the switch term of the noise model).
  static constexpr int omega_dim =
      scheduled ? 1 + (Hysteresis ? 4 : 0) + (Order == 2 ? 1 : 0) + Basis : (Hysteresis ? 5 : 1);
  static constexpr int max_half_window = MaxHalfWindow;
  static constexpr int block_length = 64;
  // Hysteresis look-back and look-ahead: samples n - 2W - 2 .. n.
  static constexpr int ring_size = Hysteresis ? 2 * MaxHalfWindow + 3 : 1;

  // Offsets and lengths of the moment vector's parts (packed = upper triangle row by row).
  struct MomentLayout {
    static constexpr int scatter = 0;  // packed sum [z, e][z, e]^T (working coordinates)
    static constexpr int scatter_size = augmented_size * (augmented_size + 1) / 2;
    static constexpr int cross = scatter + scatter_size;  // sum z b^T, row-major columns x states
    static constexpr int cross_size = columns * states;
    static constexpr int extra_cross = cross + cross_size;  // sum e b^T, row-major
    static constexpr int extra_cross_size = extras * states;
    static constexpr int gram = extra_cross + extra_cross_size;  // packed sum b b^T
    static constexpr int gram_size = states * (states + 1) / 2;
    static constexpr int omega = gram + gram_size;  // packed sum omega omega^T
    static constexpr int omega_size = omega_dim * (omega_dim + 1) / 2;
    static constexpr int rows = omega + omega_size;  // number of rows (not forgetting-weighted)
    static constexpr int size = rows + 1;
  };

  using Config = SvfConfig<Scalar>;
  using Result = SvfResult<Scalar, Order, columns>;
  using Row = Eigen::Matrix<Scalar, columns, 1>;
  using Matrix = Eigen::Matrix<Scalar, columns, columns>;
  using StateVector = Eigen::Matrix<Scalar, states, 1>;
  using MomentVector = Eigen::Matrix<double, MomentLayout::size, 1>;
  using OmegaMatrix = Eigen::Matrix<Scalar, omega_dim, omega_dim>;

  SvfEstimator() noexcept { reset(); }

  // On an invalid configuration returns invalid_argument and leaves the estimator as it was.
  Status configure(const Config& config) noexcept {
    const Scalar ts = config.sample_interval;
    const Scalar tf = config.filter_time_constant;
    if (!(ts > Scalar(0)) || !(tf > Scalar(0)) || !std::isfinite(ts) || !std::isfinite(tf)) {
      return Status::invalid_argument;
    }
    const double h = double(ts) / double(tf);
    // Below 1e-7 the transient window ((60 + 2m)/h rows) and the Lyapunov doubling run out of
    // range; above 100 the filter is far faster than the sampling and carries no information.
    if (!(h >= 1e-7 && h <= 100.0)) return Status::invalid_argument;
    const bool noise_ok = config.sigma1 >= Scalar(0) && config.sigma2 >= Scalar(0) &&
                          std::isfinite(config.sigma1) && std::isfinite(config.sigma2);
    const bool forgetting_ok = config.forgetting > Scalar(0) && config.forgetting <= Scalar(1);
    if (!noise_ok || !forgetting_ok) return Status::invalid_argument;
    if (Hysteresis) {
      const bool windows_ok =
          config.direction_half_window1 >= 1 && config.direction_half_window1 <= MaxHalfWindow &&
          config.direction_half_window2 >= 1 && config.direction_half_window2 <= MaxHalfWindow;
      const bool dead_zone_ok = config.dead_zone >= Scalar(0) && std::isfinite(config.dead_zone);
      if (!windows_ok || !dead_zone_ok) return Status::invalid_argument;
    }
    config_ = config;
    foh_.set(h, true);
    zoh_.set(h, false);
    noise_covariance_ = unsplit_noise_covariance(h, double(config.sigma1), double(config.sigma2));
    transient_rows_ =
        static_cast<std::uint64_t>(std::ceil((60.0 + 2.0 * states) / h)) + std::uint64_t(1);
    window_[0] = Hysteresis ? config.direction_half_window1 : 0;
    window_[1] = Hysteresis ? config.direction_half_window2 : 0;
    delay_ = window_[0] > window_[1] ? window_[0] : window_[1];
    for (int i = 0; i < 2; ++i) {
      const Scalar sigma = i == 0 ? config.sigma1 : config.sigma2;
      dead_zone_squared_[i] = config.dead_zone * config.dead_zone * sigma * sigma;
    }
    slope_scale_ = tf / ts;
    forgetting_ = config.forgetting < Scalar(1);
    reset();
    return Status::ok;
  }

  void reset() noexcept {
    state_ = State{};
    state_.basis.setZero();
    state_.basis[0] = Scalar(1);  // b(0) = e_0
    samples_ = 0;
    hold_ = 0;
    head_ = 0;
    offset1_ = Scalar(0);
    offset2_ = Scalar(0);
  }

  // Without a schedule (Basis == 0).
  template <int B = Basis, typename std::enable_if<B == 0, int>::type = 0>
  Status update(Scalar t1, Scalar t2) noexcept {
    if (!std::isfinite(t1) || !std::isfinite(t2)) return Status::non_finite_input;
    if (samples_ == 0) {
      offset1_ = t1;
      offset2_ = t2;
    }
    const Scalar u1 = t1 - offset1_;
    const Scalar u2 = t2 - offset2_;
    if constexpr (Hysteresis) {
      push_ring(u1, u2, Weights::Zero());
    } else {
      if (samples_ > 0) {
        foh_.step(state_.v1, state_.u1, u1);
        foh_.step(state_.v2, state_.u2, u2);
      }
      state_.u1 = u1;
      state_.u2 = u2;
      ++samples_;
      if (hold_ > 0) {
        --hold_;
        skip_row(state_);
      } else {
        accumulate(state_, unsplit_row(state_.v1, state_.v2), Extra::Ones(), OmegaRow::Zero());
      }
    }
    return Status::ok;
  }

  // With a schedule (Basis == K >= 1): `weights` points to the K weights b_1(k)..b_K(k) of this
  // sample (K = 1: psi(k) > 0); `phi` is used by order 2 only (phi(k) > 0, the caller's 1/psi).
  // Non-finite values: non_finite_input; psi (K = 1) or phi (order 2) <= 0: invalid_argument;
  // either way the estimator is left as it was.
  template <int B = Basis, typename std::enable_if<(B >= 1), int>::type = 0>
  Status update(Scalar t1, Scalar t2, const Scalar* weights, Scalar phi) noexcept {
    if (!std::isfinite(t1) || !std::isfinite(t2)) return Status::non_finite_input;
    Weights w;
    for (int j = 0; j < Basis; ++j) {
      w[j] = weights[j];
      if (!std::isfinite(w[j])) return Status::non_finite_input;
    }
    if (Order == 2 && !std::isfinite(phi)) return Status::non_finite_input;
    if (Basis == 1 && !(w[0] > Scalar(0))) return Status::invalid_argument;
    if (Order == 2 && !(phi > Scalar(0))) return Status::invalid_argument;
    if (Order == 1) phi = Scalar(1);  // unused
    if (samples_ == 0) {
      offset1_ = t1;
      offset2_ = t2;
      state_.first = w;
    }
    const Scalar u1 = t1 - offset1_;
    const Scalar u2 = t2 - offset2_;
    if constexpr (Hysteresis) {
      push_ring(u1, u2, w);
    } else {
      if (samples_ > 0) {
        foh_.step(state_.v1, state_.u1, u1);
        foh_.step(state_.v2, state_.u2, u2);
        step_schedule(state_, state_.u1, state_.u2, state_.weights, state_.phi, u1, u2, w, phi);
      }
      state_.u1 = u1;
      state_.u2 = u2;
      state_.weights = w;
      state_.phi = phi;
      ++samples_;
      OmegaRow omega;
      omega[0] = Scalar(1);
      if constexpr (Order == 2) omega[1] = phi;
      for (int j = 0; j < Basis; ++j) omega[omega_basis + j] = w[j];
      if (hold_ > 0) {
        --hold_;
        skip_row(state_);
      } else {
        accumulate(state_, scheduled_row(state_), offset_regressors(state_), omega);
      }
    }
    return Status::ok;
  }

  // K = 1 convenience: phi = 1/psi.
  template <int B = Basis, typename std::enable_if<B == 1, int>::type = 0>
  Status update(Scalar t1, Scalar t2, Scalar psi) noexcept {
    if (!std::isfinite(psi)) return Status::non_finite_input;
    const Scalar phi = psi > Scalar(0) ? Scalar(1) / psi : Scalar(1);  // psi <= 0 refused below
    return update(t1, t2, &psi, phi);
  }

  // A gap in the samples (e.g. a sensor fault; not for the hysteresis variant, where it does
  // nothing): the next sample is joined to the last one before the gap by one interval, which
  // puts a transient into the filter cascades (an input step of the change over the gap). The
  // rows of the next `settle_rows` samples advance the cascades but are not accumulated: the
  // transient decays as (t/tf)^m e^(-t/tf), so settle_rows = 25 tf/Ts leaves ~1e-8 of it. The
  // accumulated moments, and so the estimate, survive the gap. The start-up transient basis
  // keeps advancing with the skipped rows, so its projection stays aligned.
  // At most 65535 rows (capped).
  void break_chain(std::uint64_t settle_rows) noexcept {
    if constexpr (!Hysteresis) {
      hold_ = std::uint16_t(settle_rows < 65535u ? settle_rows : 65535u);
    }
  }

  Result solve() const noexcept { return solve(moments(), offset1_, offset2_); }

  // Solve from a moment vector (e.g. a sum of block moments) with this estimator's
  // configuration and first samples, or with the first samples T1(0), T2(0) given.
  Result solve(const MomentVector& m) const noexcept { return solve(m, offset1_, offset2_); }
  Result solve(const MomentVector& m, Scalar offset1, Scalar offset2) const noexcept {
    return solve_moments(unpack(m), offset1, offset2);
  }

  // What solve() reads (the hysteresis variant: including the last w rows, whose look-ahead is
  // clipped by the end of the record, run on a copy).
  MomentVector moments() const noexcept {
    if constexpr (Hysteresis) {
      return moment_vector(finished());
    } else {
      return moment_vector(state_);
    }
  }
  // The rows accumulated so far (the hysteresis variant lags by its delay, max(w1, w2) rows):
  // consecutive snapshots differ by the rows in between.
  MomentVector accumulated_moments() const noexcept { return moment_vector(state_); }

  const Config& config() const noexcept { return config_; }
  std::uint64_t samples() const noexcept { return samples_; }
  // The first samples T1(0), T2(0) (the centring offsets; 0 before the first sample).
  Scalar offset1() const noexcept { return offset1_; }
  Scalar offset2() const noexcept { return offset2_; }
  // Forgetting-weighted number of accumulated rows (the hysteresis variant lags by the delay).
  Scalar rows() const noexcept {
    if constexpr (scheduled) {
      return omega_moments(state_)(0, 0);
    } else {
      return augmented(state_)(columns, columns);
    }
  }
  // Accumulated moments of omega (see the file comment), forgetting-weighted.
  OmegaMatrix omega_moments() const noexcept { return omega_moments(state_); }
  // The projected scatter that solve() hands to GTLS (documented column order).
  Matrix scatter() const noexcept {
    return documented(projected_scatter(unpack(moments()), offset1_, offset2_))
        .template cast<Scalar>();
  }
  // Noise covariance of one unsplit, unscheduled row for the configured sigma1, sigma2
  // (documented order): C0 of the file comment.
  Eigen::Matrix<Scalar, unsplit_columns, unsplit_columns> noise_covariance() const noexcept {
    return documented(noise_covariance_).template cast<Scalar>();
  }
  // The accumulated noise covariance that solve() hands to GTLS (documented order).
  Matrix accumulated_noise_covariance() const noexcept {
    return accumulated_noise_covariance(moments());
  }
  // The same two for a moment vector (a total minus a block): what solve(m, ...) hands to
  // GTLS, for sub-model solves of resampled moments.
  Matrix scatter(const MomentVector& m, Scalar offset1, Scalar offset2) const noexcept {
    return documented(projected_scatter(unpack(m), offset1, offset2)).template cast<Scalar>();
  }
  Matrix accumulated_noise_covariance(const MomentVector& m) const noexcept {
    const Unpacked u = unpack(m);
    return documented(noise_moment(u, row_weight(u))).template cast<Scalar>();
  }

 private:
  using Augmented = Eigen::Matrix<Scalar, augmented_size, 1>;
  using AugmentedMatrix = Eigen::Matrix<Scalar, augmented_size, augmented_size>;
  using Packed = Eigen::Matrix<Scalar, augmented_size*(augmented_size + 1) / 2, 1>;
  using Extra = Eigen::Matrix<Scalar, extras, 1>;
  using OmegaRow = Eigen::Matrix<Scalar, omega_dim, 1>;
  using Weights = Eigen::Matrix<Scalar, (Basis > 0 ? Basis : 1), 1>;
  // The noise model in the working precision: its float rounding (1e-7) is far below its own
  // accuracy as a model, and it takes a sixth of the second-order estimator.
  using UnsplitMatrix = Eigen::Matrix<Scalar, unsplit_columns, unsplit_columns>;
  using SolveMatrix = Eigen::Matrix<SolveScalar, columns, columns>;
  using SolveRow = Eigen::Matrix<SolveScalar, columns, 1>;
  using SolveAugmented = Eigen::Matrix<SolveScalar, augmented_size, augmented_size>;
  // omega index of b_1 (and of phi for order 2: 1).
  static constexpr int omega_basis = 1 + (Hysteresis ? 2 : 0) + (Order == 2 ? 1 : 0);
  // omega index of p_1 (hysteresis; the last two entries).
  static constexpr int omega_previous = omega_dim - 2;
  static constexpr int ring_width = scheduled ? 3 : 2;  // u1, u2 (, psi)

  // Hysteresis only: heat1, cool1, heat2, cool2 cascades and the classification windows
  // (an empty base otherwise, so the other variants carry none of it).
  template <bool Split, typename Unused = void>
  struct SplitState {};
  template <typename Unused>
  struct SplitState<true, Unused> {
    Eigen::Matrix<Scalar, states, 4> split{Eigen::Matrix<Scalar, states, 4>::Zero()};
    std::array<svf_detail::WindowSum<Scalar>, 2> before{};
    std::array<svf_detail::WindowSum<Scalar>, 2> after{};
    // Each sensor's h on the previous row: undecided (1/2) before the first interval, as the
    // scheduled variant's first row counts.
    std::array<Scalar, 2> previous{{Scalar(0.5), Scalar(0.5)}};
  };

  // Schedule only: the cascades of the static columns (working coordinates: unit b_j (u2 - u1);
  // affine psi (u2 - u1) and psi u1), of the offset regressors (input b_j - b_j(0)), of y_1
  // (order 2, ZOH), and the last and first weights.
  template <bool Schedule, typename Unused = void>
  struct ScheduleState {};
  template <std::size_t N>
  static std::array<StateVector, N> at_rest() noexcept {
    std::array<StateVector, N> cascades;
    for (auto& v : cascades) v.setZero();  // Eigen leaves fixed-size matrices uninitialised
    return cascades;
  }
  template <typename Unused>
  struct ScheduleState<true, Unused> {
    std::array<StateVector, std::size_t(static_columns)> statics{
        at_rest<std::size_t(static_columns)>()};
    std::array<StateVector, std::size_t(extras)> offsets{at_rest<std::size_t(extras)>()};
    std::array<StateVector, std::size_t(Order == 2 ? 2 : 0)> slopes{
        at_rest<std::size_t(Order == 2 ? 2 : 0)>()};
    Weights weights{Weights::Zero()};
    Weights first{Weights::Zero()};
    Scalar phi{1};
  };

  // Everything a row changes. solve() copies it to run the hysteresis tail.
  struct State : SplitState<Hysteresis>, ScheduleState<scheduled> {
    // Block-summed moments of [z, e] and (hysteresis, schedule) of omega.
    SymmetricScatter<Scalar, augmented_size> block{};
    // Upper triangles, row by row; the sum is total - compensation (Kahan).
    Packed total{Packed::Zero()};
    Packed compensation{Packed::Zero()};
    SymmetricScatter<Scalar, omega_dim> omega_block{};
    OmegaMatrix omega_total{OmegaMatrix::Zero()};
    Scalar block_decay{1};  // forgetting^(rows in the block)
    int block_rows{0};
    // Free-response (start-up transient) moments: sum z b^T, sum b b^T and sum e b^T.
    Eigen::Matrix<Scalar, columns, states> cross{Eigen::Matrix<Scalar, columns, states>::Zero()};
    Eigen::Matrix<Scalar, states, states> gram{Eigen::Matrix<Scalar, states, states>::Zero()};
    Eigen::Matrix<Scalar, extras, states> extra_cross{
        Eigen::Matrix<Scalar, extras, states>::Zero()};
    StateVector basis{StateVector::Zero()};
    Scalar transient_decay{1};  // forgetting^(rows since the transient window closed)
    std::uint64_t rows{0};
    // Filter cascades of the static / unsplit columns and the last centred inputs.
    StateVector v1{StateVector::Zero()};
    StateVector v2{StateVector::Zero()};
    Scalar u1{0};
    Scalar u2{0};
  };

  // A moment vector in the solve precision.
  struct Unpacked {
    SolveAugmented a;
    Eigen::Matrix<SolveScalar, columns, states> cross;
    Eigen::Matrix<SolveScalar, extras, states> extra_cross;
    Eigen::Matrix<SolveScalar, states, states> gram;
    Eigen::Matrix<SolveScalar, omega_dim, omega_dim> omega;
    SolveScalar rows;
  };

  // Working -> documented coordinates of a row moment: z_doc = B z_work, B the identity but for
  // the affine static pair, (-x_0(T2), -x_0(T1)) = (-d + s, s) (scheduled: psi inside F).
  template <typename T, int N>
  static Eigen::Matrix<T, N, N> documented(const Eigen::Matrix<T, N, N>& m) noexcept {
    if constexpr (!affine) {
      return m;
    } else {
      Eigen::Matrix<T, N, N> b = Eigen::Matrix<T, N, N>::Identity();
      b(N - 2, N - 2) = T(-1);
      b(N - 2, N - 1) = T(1);
      return b * m * b.transpose();
    }
  }

  UnsplitMatrix unsplit_noise_covariance(double h, double sigma1, double sigma2) const noexcept {
    using Discretisation = SvfDiscretisation<states>;
    const auto disc = Discretisation::make(h, true);
    const auto lmap = Discretisation::derivative_map();
    const Eigen::Matrix<double, states, states> cov_x =
        lmap * disc.state_covariance * lmap.transpose();
    // Column maps z = M1 x(T1) + M2 x(T2) in working coordinates.
    Eigen::Matrix<double, unsplit_columns, states> m1 =
        Eigen::Matrix<double, unsplit_columns, states>::Zero();
    Eigen::Matrix<double, unsplit_columns, states> m2 = m1;
    for (int j = 1; j <= Order; ++j) {
      m1(j - 1, j) = 1.0;
      m2(Order + j - 1, j) = -1.0;
    }
    m1(2 * Order, 0) = -1.0;
    m2(2 * Order, 0) = 1.0;
    if (affine) m1(2 * Order + 1, 0) = -1.0;
    Eigen::Matrix<double, unsplit_columns, unsplit_columns> c =
        sigma1 * sigma1 * (m1 * cov_x * m1.transpose()) +
        sigma2 * sigma2 * (m2 * cov_x * m2.transpose());
    c = 0.5 * (c + c.transpose()).eval();
    return c.template cast<Scalar>();
  }

  // Unsplit row from the two cascades (centred: the offsets are added back in solve()).
  static Row unsplit_row(const StateVector& v1, const StateVector& v2) noexcept {
    const auto x1 = svf_derivatives<states>(v1);
    const auto x2 = svf_derivatives<states>(v2);
    Row z;
    for (int j = 1; j <= Order; ++j) {
      z[j - 1] = x1[j];
      z[Order + j - 1] = -x2[j];
    }
    z[2 * Order] = x2[0] - x1[0];
    if constexpr (affine) z[2 * Order + 1] = -x1[0];  // working coordinates (file comment)
    return z;
  }

  // Advances the schedule's cascades over one interval from (u1a, u2a, wa, phia) at sample k to
  // (u1b, u2b, wb, phib) at k + 1 (the derivative cascades are stepped by the caller).
  void step_schedule(State& s, Scalar u1a, Scalar u2a, const Weights& wa, Scalar phia,
                     Scalar u1b, Scalar u2b, const Weights& wb, Scalar phib) const noexcept {
    if constexpr (scheduled) {
      if constexpr (affine) {
        foh_.step(s.statics[0], wa[0] * (u2a - u1a), wb[0] * (u2b - u1b));
        foh_.step(s.statics[1], wa[0] * u1a, wb[0] * u1b);
      } else {
        for (std::size_t j = 0; j < std::size_t(Basis); ++j) {
          const auto i = Eigen::Index(j);
          foh_.step(s.statics[j], wa[i] * (u2a - u1a), wb[i] * (u2b - u1b));
        }
      }
      for (std::size_t j = 0; j < std::size_t(extras); ++j) {
        const auto i = Eigen::Index(j);
        foh_.step(s.offsets[j], wa[i] - s.first[i], wb[i] - s.first[i]);
      }
      if constexpr (Order == 2) {
        const Scalar mean_phi = Scalar(0.5) * (phia + phib);
        zoh_.step(s.slopes[0], mean_phi * ((u1b - u1a) * slope_scale_), Scalar(0));
        zoh_.step(s.slopes[1], mean_phi * ((u2b - u2a) * slope_scale_), Scalar(0));
      }
    } else {
      (void)s, (void)u1a, (void)u2a, (void)wa, (void)phia, (void)u1b, (void)u2b, (void)wb,
          (void)phib;
    }
  }

  // The static columns of a scheduled row (working coordinates) into z from `first_static`.
  void static_columns_into(const State& s, Row& z) const noexcept {
    if constexpr (scheduled) {
      constexpr int first_static = dynamic_columns;
      if constexpr (affine) {
        z[first_static] = s.statics[0][states - 1];
        z[first_static + 1] = -s.statics[1][states - 1];
      } else {
        for (int j = 0; j < Basis; ++j) z[first_static + j] = s.statics[std::size_t(j)][states - 1];
      }
    } else {
      (void)s, (void)z;
    }
  }

  // Scheduled row without the split (centred).
  Row scheduled_row(const State& s) const noexcept {
    Row z;
    if constexpr (scheduled && !Hysteresis) {
      const auto x1 = svf_derivatives<states>(s.v1);
      const auto x2 = svf_derivatives<states>(s.v2);
      if constexpr (Order == 1) {
        z[0] = x1[1];
        z[1] = -x2[1];
      } else {
        z[0] = x1[1];
        z[1] = svf_derivatives<states>(s.slopes[0])[1];
        z[2] = -x2[1];
        z[3] = -svf_derivatives<states>(s.slopes[1])[1];
      }
      static_columns_into(s, z);
    } else {
      (void)s;
      z.setZero();
    }
    return z;
  }

  // The offset regressors r_j = F(b_j) (steady state at b_j(0)); 1 without a schedule.
  Extra offset_regressors(const State& s) const noexcept {
    Extra e;
    if constexpr (scheduled) {
      for (int j = 0; j < extras; ++j) e[j] = s.offsets[std::size_t(j)][states - 1] + s.first[j];
    } else {
      (void)s;
      e.setOnes();
    }
    return e;
  }

  // Hysteresis: the sample into the delay line, then the row whose look-ahead is complete.
  void push_ring(Scalar u1, Scalar u2, const Weights& w) noexcept {
    if constexpr (Hysteresis) {
      head_ = samples_ == 0 ? 0 : (head_ + 1 == std::size_t(ring_size) ? 0 : head_ + 1);
      ring_[head_][0] = u1;
      ring_[head_][1] = u2;
      if constexpr (scheduled) ring_[head_][2] = w[0];
      ++samples_;
      const std::uint64_t n = samples_ - 1;
      // Fill the look-ahead windows of interval 0 (samples 2 .. w + 1).
      for (int i = 0; i < 2; ++i) {
        if (n >= 2 && n <= std::uint64_t(window_[i]) + 1) {
          state_.after[i].grow(i == 0 ? u1 : u2, window_[i]);
        }
      }
      if (n >= std::uint64_t(delay_)) process_split_row(state_, n - std::uint64_t(delay_), false);
    }
    (void)u1, (void)u2, (void)w;
  }

  // The hysteresis tail (clipped look-ahead) on a copy of the state.
  State finished() const noexcept {
    State s = state_;
    if constexpr (Hysteresis) {
      const std::uint64_t first = samples_ > std::uint64_t(delay_) ? samples_ - delay_ : 0;
      for (std::uint64_t r = first; r < samples_; ++r) process_split_row(s, r, true);
    }
    return s;
  }

  Scalar centred(int sensor, std::uint64_t index) const noexcept {
    // index lies within the last ring_size samples (guaranteed by the callers); sensor 2: psi
    const std::size_t back = static_cast<std::size_t>(samples_ - 1 - index);
    const std::size_t pos = head_ >= back ? head_ - back : head_ + std::size_t(ring_size) - back;
    return ring_[pos][static_cast<std::size_t>(sensor)];
  }

  // Heating (1), cooling (0) or undecided (1/2) for the difference of the window means.
  Scalar direction(int sensor, Scalar after_sum, Scalar after_count, Scalar before_sum,
                   Scalar before_count) const noexcept {
    const Scalar d = after_sum / after_count - before_sum / before_count;
    const Scalar threshold = dead_zone_squared_[sensor] *
                             (Scalar(1) / after_count + Scalar(1) / before_count);
    if (threshold > Scalar(0) && d * d < threshold) return Scalar(0.5);
    return d > Scalar(0) ? Scalar(1) : Scalar(0);
  }

  // Row r of the hysteresis variant (interval k = r - 1 between samples k and k + 1). `tail`:
  // the record ends at samples_ - 1 and the look-ahead windows are clipped there.
  void process_split_row(State& s, std::uint64_t r, bool tail) const noexcept {
    if constexpr (!Hysteresis) {
      (void)s;
      (void)r;
      (void)tail;
    } else {
      if (r == 0) {  // filters at rest, no interval yet
        OmegaRow omega = OmegaRow::Zero();
        if constexpr (scheduled) {
          omega[0] = Scalar(1);
          omega[1] = Scalar(0.5);  // undecided (the split columns are zero in this row)
          omega[2] = Scalar(0.5);
          omega[omega_basis] = s.first[0];
          omega[omega_previous] = s.previous[0];
          omega[omega_previous + 1] = s.previous[1];
        }
        accumulate(s, Row::Zero(), offset_regressors(s), omega);
        return;
      }
      const std::uint64_t k = r - 1;
      const std::uint64_t last = samples_ - 1;
      OmegaRow omega;
      omega[0] = Scalar(1);
      for (int i = 0; i < 2; ++i) {
        const int w = window_[i];
        const std::uint64_t wu = std::uint64_t(w);
        // Look-back T[max(k-w,0) .. max(k,1)-1]: T[0] alone for k = 0, as the reference clips.
        Scalar before_sum = Scalar(0);  // centred T[0]
        Scalar before_count = Scalar(1);
        auto& back = s.before[static_cast<std::size_t>(i)];
        if (k >= 1) {
          if (back.full(w)) {
            back.slide(centred(i, k - 1), centred(i, k - 1 - wu), w);
          } else {
            back.grow(centred(i, k - 1), w);
          }
          before_sum = back.sum();
          before_count = Scalar(back.size);
        }
        // Look-ahead T[k+2 .. k+1+w], clipped to T[min(k+2, last) .. min(k+1+w, last)].
        Scalar after_sum = Scalar(0);
        Scalar after_count = Scalar(0);
        if (!tail) {
          auto& ahead = s.after[static_cast<std::size_t>(i)];
          if (k >= 1) ahead.slide(centred(i, k + 1 + wu), centred(i, k + 1), w);
          after_sum = ahead.sum();
          after_count = Scalar(w);
        } else {
          const std::uint64_t lo = k + 2 < last ? k + 2 : last;
          const std::uint64_t hi = k + 1 + wu < last ? k + 1 + wu : last;
          for (std::uint64_t j = lo; j <= hi; ++j) after_sum += centred(i, j);
          after_count = Scalar(hi - lo + 1);
        }
        const Scalar h = direction(i, after_sum, after_count, before_sum, before_count);
        omega[i + 1] = h;
        omega[omega_previous + i] = s.previous[static_cast<std::size_t>(i)];
        s.previous[static_cast<std::size_t>(i)] = h;
        const Scalar now = centred(i, k);
        const Scalar next = centred(i, k + 1);
        const Scalar slope = (next - now) * slope_scale_;
        StateVector heating = s.split.col(2 * i);
        StateVector cooling = s.split.col(2 * i + 1);
        zoh_.step(heating, slope * h, Scalar(0));
        zoh_.step(cooling, slope * (Scalar(1) - h), Scalar(0));
        s.split.col(2 * i) = heating;
        s.split.col(2 * i + 1) = cooling;
        if constexpr (!scheduled) foh_.step(i == 0 ? s.v1 : s.v2, now, next);
      }
      Row z;
      z[0] = s.split(states - 1, 0);
      z[1] = s.split(states - 1, 1);
      z[2] = -s.split(states - 1, 2);
      z[3] = -s.split(states - 1, 3);
      if constexpr (scheduled) {
        Weights wa;
        Weights wb;
        wa[0] = centred(2, k);
        wb[0] = centred(2, k + 1);
        step_schedule(s, centred(0, k), centred(1, k), wa, Scalar(1), centred(0, k + 1),
                      centred(1, k + 1), wb, Scalar(1));
        static_columns_into(s, z);
        omega[omega_basis] = wb[0];
      } else {
        z[4] = s.v2[states - 1] - s.v1[states - 1];
        if constexpr (affine) z[5] = -s.v1[states - 1];  // working coordinates
      }
      accumulate(s, z, offset_regressors(s), omega);
    }
  }

  void accumulate(State& s, const Row& z, const Extra& extra, const OmegaRow& omega) const
      noexcept {
    constexpr bool with_omega = Hysteresis || scheduled;
    Augmented augmented;
    augmented.template head<columns>() = z;
    augmented.template tail<extras>() = extra;
    const Scalar lambda = config_.forgetting;
    if (forgetting_) {
      s.block.add(augmented, lambda);
      if constexpr (with_omega) s.omega_block.add(omega, lambda);
      s.block_decay *= lambda;
    } else {
      s.block.add(augmented);
      if constexpr (with_omega) s.omega_block.add(omega);
    }
    (void)omega;
    if (++s.block_rows == block_length) {
      const AugmentedMatrix block = s.block.matrix();
      int index = 0;
      for (int row = 0; row < augmented_size; ++row) {
        for (int col = row; col < augmented_size; ++col, ++index) {
          const Scalar carried = s.block_decay * s.total[index];
          const Scalar increment = block(row, col) - s.block_decay * s.compensation[index];
          const Scalar sum = carried + increment;
          s.compensation[index] = (sum - carried) - increment;
          s.total[index] = sum;
        }
      }
      s.block.reset();
      if constexpr (with_omega) {
        s.omega_total = (s.block_decay * s.omega_total + s.omega_block.matrix()).eval();
        s.omega_block.reset();
      }
      s.block_decay = Scalar(1);
      s.block_rows = 0;
    }
    if (s.rows < transient_rows_) {
      if (forgetting_) {
        s.cross *= lambda;
        s.gram *= lambda;
        s.extra_cross *= lambda;
      }
      s.cross.noalias() += z * s.basis.transpose();
      s.gram.noalias() += s.basis * s.basis.transpose();
      s.extra_cross.noalias() += extra * s.basis.transpose();
      foh_.propagate(s.basis);
    } else if (forgetting_ && s.transient_decay > Scalar(0)) {
      s.transient_decay *= lambda;
      // Far below rounding of the scatter: drop it before it underflows to denormals.
      if (s.transient_decay < std::numeric_limits<Scalar>::epsilon() *
                                  std::numeric_limits<Scalar>::epsilon()) {
        s.transient_decay = Scalar(0);
      }
    }
    ++s.rows;
  }

  // A row index that passes without a row (break_chain): the transient basis advances.
  void skip_row(State& s) const noexcept {
    if (s.rows < transient_rows_) foh_.propagate(s.basis);
    ++s.rows;
  }

  static AugmentedMatrix augmented(const State& s) noexcept {
    AugmentedMatrix out = s.block.matrix();
    int index = 0;
    for (int row = 0; row < augmented_size; ++row) {
      for (int col = row; col < augmented_size; ++col, ++index) {
        out(row, col) += s.block_decay * (s.total[index] - s.compensation[index]);
        out(col, row) = out(row, col);
      }
    }
    return out;
  }

  static OmegaMatrix omega_moments(const State& s) noexcept {
    return s.block_decay * s.omega_total + s.omega_block.matrix();
  }

  MomentVector moment_vector(const State& s) const noexcept {
    using L = MomentLayout;
    MomentVector out;
    const AugmentedMatrix a = augmented(s);
    int index = L::scatter;
    for (int row = 0; row < augmented_size; ++row) {
      for (int col = row; col < augmented_size; ++col) out[index++] = double(a(row, col));
    }
    const double decay = double(s.transient_decay);
    index = L::cross;
    for (int i = 0; i < columns; ++i) {
      for (int j = 0; j < states; ++j) out[index++] = decay * double(s.cross(i, j));
    }
    index = L::extra_cross;
    for (int i = 0; i < extras; ++i) {
      for (int j = 0; j < states; ++j) out[index++] = decay * double(s.extra_cross(i, j));
    }
    index = L::gram;
    for (int i = 0; i < states; ++i) {
      for (int j = i; j < states; ++j) out[index++] = decay * double(s.gram(i, j));
    }
    index = L::omega;
    if constexpr (Hysteresis || scheduled) {
      const OmegaMatrix omega = omega_moments(s);
      for (int i = 0; i < omega_dim; ++i) {
        for (int j = i; j < omega_dim; ++j) out[index++] = double(omega(i, j));
      }
    } else {
      out[index] = double(a(columns, columns));  // omega = [1]: the weighted row count
    }
    out[L::rows] = double(s.rows);
    return out;
  }

  static Unpacked unpack(const MomentVector& m) noexcept {
    using L = MomentLayout;
    using T = SolveScalar;
    Unpacked u;
    int index = L::scatter;
    for (int row = 0; row < augmented_size; ++row) {
      for (int col = row; col < augmented_size; ++col, ++index) {
        u.a(row, col) = T(m[index]);
        u.a(col, row) = u.a(row, col);
      }
    }
    index = L::cross;
    for (int i = 0; i < columns; ++i) {
      for (int j = 0; j < states; ++j) u.cross(i, j) = T(m[index++]);
    }
    index = L::extra_cross;
    for (int i = 0; i < extras; ++i) {
      for (int j = 0; j < states; ++j) u.extra_cross(i, j) = T(m[index++]);
    }
    index = L::gram;
    for (int i = 0; i < states; ++i) {
      for (int j = i; j < states; ++j, ++index) {
        u.gram(i, j) = T(m[index]);
        u.gram(j, i) = u.gram(i, j);
      }
    }
    index = L::omega;
    for (int i = 0; i < omega_dim; ++i) {
      for (int j = i; j < omega_dim; ++j, ++index) {
        u.omega(i, j) = T(m[index]);
        u.omega(j, i) = u.omega(i, j);
      }
    }
    u.rows = T(m[L::rows]);
    return u;
  }

  // Forgetting-weighted row count.
  static SolveScalar row_weight(const Unpacked& u) noexcept {
    if constexpr (scheduled) {
      return u.omega(0, 0);
    } else {
      return u.a(columns, columns);
    }
  }

  // Scatter of the full rows with the start-up transients (and, affine, the constant or the
  // offset regressor) projected out: S - Szb Sbb^+ Szb^T (working coordinates, solve precision).
  SolveMatrix projected_scatter(const Unpacked& u, Scalar offset1,
                                Scalar offset2) const noexcept {
    using T = SolveScalar;
    SolveMatrix scatter = u.a.template topLeftCorner<columns, columns>();
    const Eigen::Matrix<T, columns, extras> first = u.a.template topRightCorner<columns, extras>();
    Eigen::Matrix<T, columns, basis_size> cross = Eigen::Matrix<T, columns, basis_size>::Zero();
    Eigen::Matrix<T, basis_size, basis_size> gram =
        Eigen::Matrix<T, basis_size, basis_size>::Zero();
    cross.template leftCols<states>() = u.cross;
    gram.template topLeftCorner<states, states>() = u.gram;
    if constexpr (affine) {
      // The constant (no schedule) or r = F(psi) joins the projected directions.
      cross.col(states) = first.col(0);
      gram.template block<states, 1>(0, states) = u.extra_cross.row(0).transpose();
      gram.template block<1, states>(states, 0) = u.extra_cross.row(0);
      gram(states, states) = u.a(columns, columns);
    } else {
      // Unit model: static column j is centred + (T2(0) - T1(0)) e_j (e = 1 or r_j).
      const T d = T(offset2) - T(offset1);
      constexpr int first_static = columns - extras;
      for (int j = 0; j < extras; ++j) scatter.col(first_static + j) += d * first.col(j);
      for (int j = 0; j < extras; ++j) {
        scatter.row(first_static + j) += d * first.col(j).transpose();
      }
      for (int i = 0; i < extras; ++i) {
        for (int j = 0; j < extras; ++j) {
          scatter(first_static + i, first_static + j) += d * d * u.a(columns + i, columns + j);
        }
      }
      for (int j = 0; j < extras; ++j) cross.row(first_static + j) += d * u.extra_cross.row(j);
    }
    // Pseudo-inverse through the eigen-decomposition of the diagonally scaled Gram matrix:
    // equal to the inverse when it is regular, and a dropped transient (forgetting) or a
    // record shorter than the basis simply contributes nothing.
    Eigen::Matrix<T, basis_size, 1> scale;
    for (int i = 0; i < basis_size; ++i) {
      scale[i] = gram(i, i) > T(0) ? T(1) / std::sqrt(gram(i, i)) : T(0);
    }
    const Eigen::Matrix<T, basis_size, basis_size> normalised =
        scale.asDiagonal() * gram * scale.asDiagonal();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix<T, basis_size, basis_size>> eig(normalised);
    if (eig.info() == Eigen::Success) {
      const auto& values = eig.eigenvalues();
      const T floor = T(256) * std::numeric_limits<T>::epsilon() * values[basis_size - 1];
      const Eigen::Matrix<T, columns, basis_size> projected =
          cross * scale.asDiagonal() * eig.eigenvectors();
      for (int j = 0; j < basis_size; ++j) {
        if (values[j] > floor) {
          scatter.noalias() -= projected.col(j) * projected.col(j).transpose() / values[j];
        }
      }
    }
    return T(0.5) * (scatter + scatter.transpose());
  }

  // Column a's noise: source column in the unsplit layout and its per-row weight
  // omega[positive] - omega[negative] (negative < 0: none).
  struct ColumnNoise {
    int source;
    int positive;
    int negative;
  };
  static constexpr ColumnNoise column_noise(int col) noexcept {
    if (col < dynamic_columns) {
      if (Hysteresis) {  // H1, K1, H2, K2: weights h_i and 1 - h_i
        const int sensor = col / 2;
        return col % 2 == 0 ? ColumnNoise{sensor, 1 + sensor, -1}
                            : ColumnNoise{sensor, 0, 1 + sensor};
      }
      // order 2: y_1 (odd positions) carries phi times the noise of x_2
      return ColumnNoise{col, (Order == 2 && col % 2 == 1) ? 1 : 0, -1};
    }
    const int j = col - dynamic_columns;
    return affine ? ColumnNoise{2 * Order + j, omega_basis, -1}
                  : ColumnNoise{2 * Order, omega_basis + j, -1};
  }

  // The split columns' noise where h changes between rows. Row k's heating column carries
  // sum_j g_{k-j} w_j (e_{j+1} - e_j) (tf/Ts) of its sensor's noise (w = h, cooling 1 - h; g
  // the ZOH cascade's response to one interval), so the columns a, b accumulate
  // sigma^2 (tf/Ts)^2 [2 G0 sum w_a w_b - G1 sum (w_a(k) w_b(k-1) + w_a(k-1) w_b(k))]. The
  // weighted C0 = sigma^2 (tf/Ts)^2 (2 G0 - 2 G1) sum w_a w_b counts all but
  // G1 [2 sum w_a w_b - lagged sums]: zero while h holds, one G1 per unit switch (a pulse of
  // the noise sample at the switch, which the differences no longer cancel), with opposite
  // signs in heating and cooling. A hysteretic drive cycle switches about once a second: left
  // out, the misfit read 2.55 times the noise with the true directions, 1.06 with it.
  // omega index of an entry's value on the row before: h_i -> p_i, the rest as they are
  // (the constant; the split's variants have no other per-row entry the switch term reads).
  static constexpr int lagged(int index) noexcept {
    return Hysteresis && (index == 1 || index == 2) ? omega_previous + index - 1 : index;
  }

  // sum_rows w_a(k) w_b(k) (``lag``: w_b(k - 1)) with w = omega[positive] - omega[negative],
  // from the omega moments m.
  template <typename T>
  static T weight_moment(const Eigen::Matrix<T, omega_dim, omega_dim>& m, const ColumnNoise& a,
                         const ColumnNoise& b, bool lag) noexcept {
    const auto at = [&m, lag](int i, int j) { return m(i, lag ? lagged(j) : j); };
    T sum = at(a.positive, b.positive);
    if (a.negative >= 0) sum -= at(a.negative, b.positive);
    if (b.negative >= 0) sum -= at(a.positive, b.negative);
    if (a.negative >= 0 && b.negative >= 0) sum += at(a.negative, b.negative);
    return sum;
  }

  template <typename T>
  void add_switch_noise(SolveMatrix& c, const Eigen::Matrix<T, omega_dim, omega_dim>& m,
                        T scale) const noexcept {
    if constexpr (Hysteresis) {
      // G1 = c' phi P c: the lag-1 sum of the split cascade's response to one interval's slope
      // (ZOH; P its stationary state covariance, c the last state), in the slope's scale
      // (tf/Ts)^2. Configuration-time arithmetic, run per solve: no member for every variant
      // (the ECU budgets below).
      const double step = double(config_.sample_interval) / double(config_.filter_time_constant);
      const auto zoh = SvfDiscretisation<states>::make(step, false);
      const double g1 = (zoh.phi * zoh.state_covariance)(states - 1, states - 1) / (step * step);
      for (int a = 0; a < dynamic_columns; ++a) {
        const ColumnNoise na = column_noise(a);
        for (int b = a; b < dynamic_columns; ++b) {
          const ColumnNoise nb = column_noise(b);
          if (na.source != nb.source) continue;  // the two sensors' noises are independent
          const double sigma = double(na.source == 0 ? config_.sigma1 : config_.sigma2);
          const T entry = scale * T(g1 * sigma * sigma) *
                          (T(2) * weight_moment(m, na, nb, false) - weight_moment(m, na, nb, true) -
                           weight_moment(m, nb, na, true));
          c(a, b) += entry;
          if (b != a) c(b, a) += entry;
        }
      }
    } else {
      (void)c;
      (void)m;
      (void)scale;
    }
  }

  // Noise covariance accumulated over the rows (sum of each row's covariance).
  SolveMatrix noise_moment(const Unpacked& u, SolveScalar weight) const noexcept {
    using T = SolveScalar;
    if constexpr (!Hysteresis && !scheduled) {
      return weight * noise_covariance_.template cast<T>();
    } else if constexpr (!scheduled) {
      // Each split row spreads its sensor's x_1 noise as (h, 1 - h) over the heating and
      // cooling columns: entry (a, b) collects sum_rows w_a(h) w_b(h) C0[ca][cb] with the
      // linear weights w = alpha + beta h, i.e. from the moments of (1, h1, h2). Rows before
      // the first interval are counted like the others (weight / interval count).
      const Eigen::Matrix<T, omega_dim, omega_dim>& m = u.omega;
      const T intervals = m(0, 0);
      SolveMatrix c = SolveMatrix::Zero();
      if (!(intervals > T(0))) return c;
      // Split column a: unsplit source column, weight alpha + beta h_which (which 0: none).
      std::array<int, columns> source{};
      std::array<int, columns> which{};
      std::array<T, columns> alpha{};
      std::array<T, columns> beta{};
      for (int col = 0; col < columns; ++col) {
        const auto a = static_cast<std::size_t>(col);
        const bool split = col < 4;
        const bool cooling = split && (col % 2 == 1);
        source[a] = split ? col / 2 : col - 2;
        which[a] = split ? col / 2 + 1 : 0;
        alpha[a] = split ? (cooling ? T(1) : T(0)) : T(1);
        beta[a] = split ? (cooling ? T(-1) : T(1)) : T(0);
      }
      const T scale = weight / intervals;
      for (std::size_t a = 0; a < std::size_t(columns); ++a) {
        for (std::size_t b = a; b < std::size_t(columns); ++b) {
          const T weights = alpha[a] * alpha[b] * m(0, 0) + alpha[a] * beta[b] * m(0, which[b]) +
                            beta[a] * alpha[b] * m(which[a], 0) +
                            beta[a] * beta[b] * m(which[a], which[b]);
          const T entry = scale * weights * T(noise_covariance_(source[a], source[b]));
          c(Eigen::Index(a), Eigen::Index(b)) = entry;
          c(Eigen::Index(b), Eigen::Index(a)) = entry;
        }
      }
      add_switch_noise(c, m, scale);
      return c;
    } else {
      // C[a][b] = C0[src a][src b] sum_rows w_a w_b with w = omega[p] - omega[n].
      (void)weight;
      const Eigen::Matrix<T, omega_dim, omega_dim>& m = u.omega;
      SolveMatrix c;
      for (int a = 0; a < columns; ++a) {
        const ColumnNoise na = column_noise(a);
        for (int b = a; b < columns; ++b) {
          const ColumnNoise nb = column_noise(b);
          const T entry =
              weight_moment(m, na, nb, false) * T(noise_covariance_(na.source, nb.source));
          c(a, b) = entry;
          c(b, a) = entry;
        }
      }
      if constexpr (Hysteresis) add_switch_noise(c, m, T(1));
      return c;
    }
  }

  Result solve_moments(const Unpacked& u, Scalar offset1, Scalar offset2) const noexcept {
    using T = SolveScalar;
    Result out;
    const T weight = row_weight(u);
    out.rows = Scalar(weight);
    // Fewer rows than unknowns plus projected directions cannot determine theta.
    if (!(u.rows >= T(columns + basis_size))) {
      out.status = Status::insufficient_excitation;
      return out;
    }
    // Back to the documented columns (exact enough in the solve precision), so that the
    // reference's diagonal scaling and regulariser act on the same coordinates.
    const SolveMatrix scatter = documented(projected_scatter(u, offset1, offset2));
    const SolveMatrix noise = documented(noise_moment(u, weight));
    // GTLS as the reference: scale by diag(S)^-1/2, regularise C, whiten with C = L L^T.
    SolveRow scale;
    for (int i = 0; i < columns; ++i) {
      const T diagonal = scatter(i, i);
      if (!(diagonal > T(0)) || !std::isfinite(diagonal)) {
        out.status = Status::insufficient_excitation;  // a column without excitation
        return out;
      }
      scale[i] = T(1) / std::sqrt(diagonal);
    }
    const SolveMatrix s_n = scale.asDiagonal() * scatter * scale.asDiagonal();
    SolveMatrix c_n = scale.asDiagonal() * noise * scale.asDiagonal();
    // The reference's 1e-12 max(trace, 1) I (noise-free data -> TLS), plus a relative
    // 16 eps on each diagonal entry for a float solve, where 1e-12 would vanish in the
    // rounding of a noisy column (an absolute floor would swamp a high-SNR column's noise).
    const T absolute = T(1e-12) * std::fmax(c_n.trace(), T(1));
    const T relative = T(16) * std::numeric_limits<T>::epsilon();
    for (int i = 0; i < columns; ++i) c_n(i, i) += absolute + relative * c_n(i, i);
    Eigen::LLT<SolveMatrix> llt(c_n);
    if (llt.info() != Eigen::Success) {
      out.status = Status::insufficient_excitation;
      return out;
    }
    // Column by column (as gtls.hpp): a matrix right-hand side instantiates Eigen's blocked
    // triangular solver, which references malloc/free (the firmware's heap guard fails the
    // link); vector solves do not.
    SolveMatrix half;
    for (int j = 0; j < columns; ++j) half.col(j) = llt.matrixL().solve(s_n.col(j));
    const SolveMatrix half_t = half.transpose();
    SolveMatrix whitened;
    for (int j = 0; j < columns; ++j) whitened.col(j) = llt.matrixL().solve(half_t.col(j));
    const SolveMatrix symmetric = T(0.5) * (whitened + whitened.transpose());
    Eigen::SelfAdjointEigenSolver<SolveMatrix> eig(symmetric);
    if (eig.info() != Eigen::Success || !symmetric.allFinite()) {
      out.status = Status::insufficient_excitation;
      return out;
    }
    const SolveRow mu = eig.eigenvalues();
    out.eigenvalues = mu.template cast<Scalar>();
    out.eigenvalue_ratio = mu[1] > T(0) ? Scalar(mu[0] / mu[1]) : Scalar(0);
    // A second eigenvalue within rounding of the largest: a null space of dimension >= 2 (too
    // few rows, or the signals do not move), no single relation to return.
    if (!(mu[1] - mu[0] > std::numeric_limits<T>::epsilon() * mu[columns - 1])) {
      out.status = Status::insufficient_excitation;
      return out;
    }
    SolveRow v = llt.matrixU().solve(eig.eigenvectors().col(0));
    v = v.cwiseProduct(scale);
    const T last = v[columns - 1];
    if (!(std::abs(last) > std::numeric_limits<T>::epsilon() * v.norm())) {
      out.status = Status::infeasible;
      return out;
    }
    const SolveRow theta = -v / last;
    if (!theta.allFinite()) {
      out.status = Status::infeasible;
      return out;
    }
    out.theta = theta.template cast<Scalar>();
    parameters(out, theta, u.a, offset1, offset2);
    return out;
  }

  // theta -> polynomials, time constants, gain ratio, offset; sets the status.
  void parameters(Result& out, const SolveRow& theta, const SolveAugmented& a, Scalar offset1,
                  Scalar offset2) const noexcept {
    using T = SolveScalar;
    const T tf = T(config_.filter_time_constant);
    const T gain = affine ? theta[dynamic_columns] : T(1);
    out.gain_ratio = Scalar(gain);
    if constexpr (affine) {
      // o = mean of theta . z over the rows (scheduled: its least-squares coefficient on r),
      // with the offsets that centring removed. In working coordinates theta = [dynamic, -g,
      // g - 1] and the offsets are T2(0) - T1(0), -T1(0) (no difference of two ~400 K values).
      SolveRow working = theta;
      working[columns - 2] = -gain;
      working[columns - 1] = gain - T(1);
      const T centred_mean =
          working.dot(a.template topRightCorner<columns, 1>()) / a(columns, columns);
      out.offset = Scalar(centred_mean - gain * (T(offset2) - T(offset1)) -
                          (gain - T(1)) * T(offset1));
    } else {
      (void)a, (void)offset1, (void)offset2;
    }
    bool ok = gain > T(0) && std::isfinite(gain);
    if constexpr (Hysteresis) {
      const T taus[4] = {theta[0] * tf, theta[1] * tf, theta[2] * tf / gain, theta[3] * tf / gain};
      for (T tau : taus) ok = ok && tau > T(0) && std::isfinite(tau);
      out.tau_heat1 = Scalar(taus[0]);
      out.tau_cool1 = Scalar(taus[1]);
      out.tau_heat2 = Scalar(taus[2]);
      out.tau_cool2 = Scalar(taus[3]);
      out.polynomial1[0] = Scalar(T(0.5) * (taus[0] + taus[1]));
      out.polynomial2[0] = Scalar(T(0.5) * (taus[2] + taus[3]));
      out.time_constants1 = out.polynomial1;
      out.time_constants2 = out.polynomial2;
    } else {
      Eigen::Matrix<T, Order, 1> p1;
      Eigen::Matrix<T, Order, 1> p2;
      T power = tf;
      for (int j = 0; j < Order; ++j) {
        p1[j] = theta[j] * power;
        p2[j] = theta[Order + j] * power / gain;
        power *= tf;
      }
      Eigen::Matrix<T, Order, 1> taus1;
      Eigen::Matrix<T, Order, 1> taus2;
      ok = roots(p1, taus1) && ok;
      ok = roots(p2, taus2) && ok;
      out.polynomial1 = p1.template cast<Scalar>();
      out.polynomial2 = p2.template cast<Scalar>();
      out.time_constants1 = taus1.template cast<Scalar>();
      out.time_constants2 = taus2.template cast<Scalar>();
    }
    out.status = ok ? Status::ok : Status::infeasible;
  }

  // Time constants of 1 + c s (+ d s^2), largest first; false (and NaN) unless real positive.
  static bool roots(const Eigen::Matrix<SolveScalar, Order, 1>& p,
                    Eigen::Matrix<SolveScalar, Order, 1>& taus) noexcept {
    using T = SolveScalar;
    const T nan = std::numeric_limits<T>::quiet_NaN();
    if constexpr (Order == 1) {
      const bool ok = p[0] > T(0) && std::isfinite(p[0]);
      taus[0] = ok ? p[0] : nan;
      return ok;
    } else {
      const T c = p[0];
      const T d = p[1];
      T disc = c * c - T(4) * d;
      // A double pole comes out with a discriminant of rounding size and either sign.
      if (disc < T(0) && -disc <= T(16) * std::numeric_limits<T>::epsilon() * c * c) disc = T(0);
      const bool ok =
          c > T(0) && d > T(0) && disc >= T(0) && std::isfinite(c) && std::isfinite(d);
      if (!ok) {
        taus.setConstant(nan);
        return false;
      }
      taus[0] = T(0.5) * (c + std::sqrt(disc));
      taus[1] = d / taus[0];  // no cancellation for the small root
      return true;
    }
  }

  State state_{};
  std::array<std::array<Scalar, ring_width>, std::size_t(ring_size)> ring_{};
  Config config_{};
  SvfCascade<Scalar, states> foh_{};
  SvfCascade<Scalar, states> zoh_{};
  UnsplitMatrix noise_covariance_{UnsplitMatrix::Zero()};
  std::uint64_t samples_{0};
  std::uint64_t transient_rows_{1};
  std::size_t head_{0};
  Scalar offset1_{0};
  Scalar offset2_{0};
  Scalar slope_scale_{1};
  std::array<Scalar, 2> dead_zone_squared_{};
  std::array<int, 2> window_{};
  int delay_{0};
  bool forgetting_{false};
  std::uint16_t hold_{0};  // rows still to skip after break_chain() (in the padding)
};

// The variants the firmware and the bindings use.
template <typename Scalar, StaticModel Static = StaticModel::unit>
using SvfFirstOrder = SvfEstimator<Scalar, 1, Static>;
template <typename Scalar, StaticModel Static = StaticModel::unit>
using SvfSecondOrder = SvfEstimator<Scalar, 2, Static>;
template <typename Scalar, StaticModel Static = StaticModel::unit, int MaxHalfWindow = 128>
using SvfHysteresis = SvfEstimator<Scalar, 1, Static, true, MaxHalfWindow>;
// Flow-scheduled variants (design.md 1.5).
template <typename Scalar, int Order, int Basis = 1, StaticModel Static = StaticModel::unit>
using SvfScheduled = SvfEstimator<Scalar, Order, Static, false, 128, double, Basis>;
template <typename Scalar, StaticModel Static = StaticModel::unit, int MaxHalfWindow = 128>
using SvfScheduledHysteresis = SvfEstimator<Scalar, 1, Static, true, MaxHalfWindow, double, 1>;

// ECU budget (state, delay line and configuration; no heap).
static_assert(sizeof(SvfFirstOrder<float>) <= 512, "first-order float SVF grew unexpectedly");
static_assert(sizeof(SvfSecondOrder<float, StaticModel::affine>) <= 1024,
              "second-order float SVF grew unexpectedly");
static_assert(sizeof(SvfHysteresis<float, StaticModel::affine>) <= 4096,
              "hysteresis float SVF (128-sample half window) grew unexpectedly");
static_assert(sizeof(SvfScheduled<float, 1>) <= 512,
              "first-order scheduled float SVF grew unexpectedly");
static_assert(sizeof(SvfScheduled<float, 2>) <= 1024,
              "second-order scheduled float SVF grew unexpectedly");
// The scheduled split: 4096 -> 4224 bytes with the previous rows' h in omega (the switch term
// of the noise model, design.md 1.4).
static_assert(sizeof(SvfScheduledHysteresis<float, StaticModel::affine>) <= 4352,
              "scheduled hysteresis float SVF (128-sample half window) grew unexpectedly");

}  // namespace dualprobe
