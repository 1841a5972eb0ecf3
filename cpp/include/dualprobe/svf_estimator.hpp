// Streaming state-variable-filter (SVF) cross-relation estimator (design.md 1.4, issues 6 and 7).
// The batch reference and full specification is python/dualprobe/reference/svf.py.
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
// update() is O(1) and allocation free: it advances the filter cascades and accumulates
//   * the scatter of the augmented row [z, 1] (so sum z z^T, sum z and the row count in one
//     SymmetricScatter), block-summed: a block of 64 rows is summed alone and then added to the
//     total with Kahan compensation, which keeps float sums at the rounding of the rows
//     themselves however long the record (plain summation: up to 10x worse on 45000 rows);
//   * during the first (60 + 2m) tf/Ts rows, sum z b^T, sum b b^T and sum b for the filter's free
//     responses b(k) = phi^k e_0: every start-up transient of the filtered columns lies in their
//     span and solve() projects it out (no warm-up samples are discarded);
//   * hysteresis: moments of the direction weights (h1, h2) for the split noise covariance.
// The signals are centred on their first samples (kept as offsets): the filter and the moments
// then work on temperature changes rather than on ~300 K absolute values.
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
template <typename Scalar, int Order, StaticModel Static = StaticModel::unit,
          bool Hysteresis = false, int MaxHalfWindow = 128, typename SolveScalar = double>
class SvfEstimator {
 public:
  static_assert(std::is_floating_point<Scalar>::value, "Scalar must be float or double");
  static_assert(Order == 1 || Order == 2, "the SVF estimator supports order 1 and 2");
  static_assert(!Hysteresis || Order == 1, "the hysteresis split is defined for order 1 only");
  static_assert(MaxHalfWindow >= 1 && MaxHalfWindow <= 65536, "direction window capacity");

  static constexpr int order = Order;
  static constexpr int states = Order + 1;  // cascade length m
  static constexpr bool affine = Static == StaticModel::affine;
  static constexpr bool hysteresis = Hysteresis;
  static constexpr int unsplit_columns = 2 * Order + (affine ? 2 : 1);
  static constexpr int columns = unsplit_columns + (Hysteresis ? 2 : 0);
  static constexpr int basis_size = states + (affine ? 1 : 0);
  static constexpr int max_half_window = MaxHalfWindow;
  static constexpr int block_length = 64;
  // Hysteresis look-back and look-ahead: samples n - 2W - 2 .. n.
  static constexpr int ring_size = Hysteresis ? 2 * MaxHalfWindow + 3 : 1;

  using Config = SvfConfig<Scalar>;
  using Result = SvfResult<Scalar, Order, columns>;
  using Row = Eigen::Matrix<Scalar, columns, 1>;
  using Matrix = Eigen::Matrix<Scalar, columns, columns>;
  using StateVector = Eigen::Matrix<Scalar, states, 1>;

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
    head_ = 0;
    offset1_ = Scalar(0);
    offset2_ = Scalar(0);
  }

  Status update(Scalar t1, Scalar t2) noexcept {
    if (!std::isfinite(t1) || !std::isfinite(t2)) return Status::non_finite_input;
    if (samples_ == 0) {
      offset1_ = t1;
      offset2_ = t2;
    }
    const Scalar u1 = t1 - offset1_;
    const Scalar u2 = t2 - offset2_;
    if constexpr (Hysteresis) {
      head_ = samples_ == 0 ? 0 : (head_ + 1 == std::size_t(ring_size) ? 0 : head_ + 1);
      ring_[head_] = {u1, u2};
      ++samples_;
      const std::uint64_t n = samples_ - 1;
      // Fill the look-ahead windows of interval 0 (samples 2 .. w + 1).
      for (int i = 0; i < 2; ++i) {
        if (n >= 2 && n <= std::uint64_t(window_[i]) + 1) {
          state_.after[i].grow(i == 0 ? u1 : u2, window_[i]);
        }
      }
      if (n >= std::uint64_t(delay_)) process_split_row(state_, n - std::uint64_t(delay_), false);
    } else {
      if (samples_ > 0) {
        foh_.step(state_.v1, state_.u1, u1);
        foh_.step(state_.v2, state_.u2, u2);
      }
      state_.u1 = u1;
      state_.u2 = u2;
      ++samples_;
      accumulate(state_, unsplit_row(state_.v1, state_.v2), DirectionRow::Zero());
    }
    return Status::ok;
  }

  Result solve() const noexcept {
    if constexpr (Hysteresis) {
      State finished = state_;  // the tail rows (clipped look-ahead) on a copy: solve stays const
      const std::uint64_t first = samples_ > std::uint64_t(delay_) ? samples_ - delay_ : 0;
      for (std::uint64_t r = first; r < samples_; ++r) process_split_row(finished, r, true);
      return solve_state(finished);
    } else {
      return solve_state(state_);
    }
  }

  const Config& config() const noexcept { return config_; }
  std::uint64_t samples() const noexcept { return samples_; }
  // Forgetting-weighted number of accumulated rows (the hysteresis variant lags by the delay).
  Scalar rows() const noexcept { return moments(state_)(columns, columns); }
  // The projected scatter that solve() hands to GTLS (documented column order).
  Matrix scatter() const noexcept {
    if constexpr (Hysteresis) {
      State finished = state_;
      const std::uint64_t first = samples_ > std::uint64_t(delay_) ? samples_ - delay_ : 0;
      for (std::uint64_t r = first; r < samples_; ++r) process_split_row(finished, r, true);
      return documented(projected_scatter(finished)).template cast<Scalar>();
    } else {
      return documented(projected_scatter(state_)).template cast<Scalar>();
    }
  }
  // Noise covariance of one unsplit row for the configured sigma1, sigma2 (documented order).
  Eigen::Matrix<Scalar, unsplit_columns, unsplit_columns> noise_covariance() const noexcept {
    return documented(noise_covariance_).template cast<Scalar>();
  }

 private:
  using Augmented = Eigen::Matrix<Scalar, columns + 1, 1>;
  using AugmentedMatrix = Eigen::Matrix<Scalar, columns + 1, columns + 1>;
  using Packed = Eigen::Matrix<Scalar, (columns + 1) * (columns + 2) / 2, 1>;
  static constexpr int direction_dim = Hysteresis ? 3 : 1;
  using DirectionRow = Eigen::Matrix<Scalar, direction_dim, 1>;
  using DirectionMatrix = Eigen::Matrix<Scalar, direction_dim, direction_dim>;
  // The noise model in the working precision: its float rounding (1e-7) is far below its own
  // accuracy as a model, and it takes a sixth of the second-order estimator.
  using UnsplitMatrix = Eigen::Matrix<Scalar, unsplit_columns, unsplit_columns>;
  using SolveMatrix = Eigen::Matrix<SolveScalar, columns, columns>;
  using SolveRow = Eigen::Matrix<SolveScalar, columns, 1>;

  // Hysteresis only: heat1, cool1, heat2, cool2 cascades and the classification windows
  // (an empty base otherwise, so the other variants carry none of it).
  template <bool Split, typename Unused = void>
  struct SplitState {};
  template <typename Unused>
  struct SplitState<true, Unused> {
    Eigen::Matrix<Scalar, states, 4> split{Eigen::Matrix<Scalar, states, 4>::Zero()};
    std::array<svf_detail::WindowSum<Scalar>, 2> before{};
    std::array<svf_detail::WindowSum<Scalar>, 2> after{};
  };

  // Everything a row changes. solve() copies it to run the hysteresis tail.
  struct State : SplitState<Hysteresis> {
    // Block-summed moments of [z, 1] and (hysteresis) of [has interval, h1, h2].
    SymmetricScatter<Scalar, columns + 1> block{};
    // Upper triangles, row by row; the sum is total - compensation (Kahan).
    Packed total{Packed::Zero()};
    Packed compensation{Packed::Zero()};
    SymmetricScatter<Scalar, direction_dim> direction_block{};
    DirectionMatrix direction_total{DirectionMatrix::Zero()};
    Scalar block_decay{1};  // forgetting^(rows in the block)
    int block_rows{0};
    // Free-response (start-up transient) moments.
    Eigen::Matrix<Scalar, columns, states> cross{Eigen::Matrix<Scalar, columns, states>::Zero()};
    Eigen::Matrix<Scalar, states, states> gram{Eigen::Matrix<Scalar, states, states>::Zero()};
    StateVector basis_sum{StateVector::Zero()};
    StateVector basis{StateVector::Zero()};
    Scalar transient_decay{1};  // forgetting^(rows since the transient window closed)
    std::uint64_t rows{0};
    // Filter cascades of the static / unsplit columns and the last centred inputs.
    StateVector v1{StateVector::Zero()};
    StateVector v2{StateVector::Zero()};
    Scalar u1{0};
    Scalar u2{0};
  };

  // Working -> documented coordinates of a row moment: z_doc = B z_work, B the identity but for
  // the affine static pair, (-x_0(T2), -x_0(T1)) = (-d + s, s).
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

  Scalar centred(int sensor, std::uint64_t index) const noexcept {
    // index lies within the last ring_size samples (guaranteed by the callers)
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
      if (r == 0) {
        accumulate(s, Row::Zero(), DirectionRow::Zero());  // filters at rest, no interval yet
        return;
      }
      const std::uint64_t k = r - 1;
      const std::uint64_t last = samples_ - 1;
      DirectionRow directions;
      directions[0] = Scalar(1);
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
        directions[i + 1] = h;
        const Scalar now = centred(i, k);
        const Scalar next = centred(i, k + 1);
        const Scalar slope = (next - now) * slope_scale_;
        StateVector heating = s.split.col(2 * i);
        StateVector cooling = s.split.col(2 * i + 1);
        zoh_.step(heating, slope * h, Scalar(0));
        zoh_.step(cooling, slope * (Scalar(1) - h), Scalar(0));
        s.split.col(2 * i) = heating;
        s.split.col(2 * i + 1) = cooling;
        foh_.step(i == 0 ? s.v1 : s.v2, now, next);
      }
      Row z;
      z[0] = s.split(states - 1, 0);
      z[1] = s.split(states - 1, 1);
      z[2] = -s.split(states - 1, 2);
      z[3] = -s.split(states - 1, 3);
        z[4] = s.v2[states - 1] - s.v1[states - 1];
      if constexpr (affine) z[5] = -s.v1[states - 1];  // working coordinates
      accumulate(s, z, directions);
  
    }
  }

  void accumulate(State& s, const Row& z, const DirectionRow& directions) const noexcept {
    Augmented augmented;
    augmented.template head<columns>() = z;
    augmented[columns] = Scalar(1);
    const Scalar lambda = config_.forgetting;
    if (forgetting_) {
      s.block.add(augmented, lambda);
      if constexpr (Hysteresis) s.direction_block.add(directions, lambda);
      s.block_decay *= lambda;
    } else {
      s.block.add(augmented);
      if constexpr (Hysteresis) s.direction_block.add(directions);
    }
    if (++s.block_rows == block_length) {
      const AugmentedMatrix block = s.block.matrix();
      int index = 0;
      for (int row = 0; row <= columns; ++row) {
        for (int col = row; col <= columns; ++col, ++index) {
          const Scalar carried = s.block_decay * s.total[index];
          const Scalar increment = block(row, col) - s.block_decay * s.compensation[index];
          const Scalar sum = carried + increment;
          s.compensation[index] = (sum - carried) - increment;
          s.total[index] = sum;
        }
      }
      s.block.reset();
      if constexpr (Hysteresis) {
        s.direction_total = (s.block_decay * s.direction_total + s.direction_block.matrix()).eval();
        s.direction_block.reset();
      }
      s.block_decay = Scalar(1);
      s.block_rows = 0;
    }
    if (s.rows < transient_rows_) {
      if (forgetting_) {
        s.cross *= lambda;
        s.gram *= lambda;
        s.basis_sum *= lambda;
      }
      s.cross.noalias() += z * s.basis.transpose();
      s.gram.noalias() += s.basis * s.basis.transpose();
      s.basis_sum += s.basis;
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

  static AugmentedMatrix moments(const State& s) noexcept {
    AugmentedMatrix out = s.block.matrix();
    int index = 0;
    for (int row = 0; row <= columns; ++row) {
      for (int col = row; col <= columns; ++col, ++index) {
        out(row, col) += s.block_decay * (s.total[index] - s.compensation[index]);
        out(col, row) = out(row, col);
      }
    }
    return out;
  }

  // Scatter of the full rows with the start-up transients (and, affine, the constant)
  // projected out: S - Szb Sbb^+ Szb^T (working coordinates, solve precision).
  SolveMatrix projected_scatter(const State& s) const noexcept {
    using T = SolveScalar;
    const Eigen::Matrix<T, columns + 1, columns + 1> a = moments(s).template cast<T>();
    SolveMatrix scatter = a.template topLeftCorner<columns, columns>();
    const SolveRow first = a.template topRightCorner<columns, 1>();
    const T weight = a(columns, columns);
    Eigen::Matrix<T, columns, basis_size> cross = Eigen::Matrix<T, columns, basis_size>::Zero();
    Eigen::Matrix<T, basis_size, basis_size> gram =
        Eigen::Matrix<T, basis_size, basis_size>::Zero();
    const T decay = T(s.transient_decay);
    const Eigen::Matrix<T, states, 1> basis_sum = s.basis_sum.template cast<T>();
    cross.template leftCols<states>() = decay * s.cross.template cast<T>();
    gram.template topLeftCorner<states, states>() = decay * s.gram.template cast<T>();
    if constexpr (affine) {
      cross.col(states) = first;
      gram.template block<states, 1>(0, states) = decay * basis_sum;
      gram.template block<1, states>(states, 0) = decay * basis_sum.transpose();
      gram(states, states) = weight;
    } else {
      // Unit model: the last column is x_0(T2) - x_0(T1) = centred + (T2(0) - T1(0)).
      const T d = T(offset2_) - T(offset1_);
      scatter.col(columns - 1) += d * first;
      scatter.row(columns - 1) += d * first.transpose();
      scatter(columns - 1, columns - 1) += d * d * weight;
      cross.row(columns - 1) += d * decay * basis_sum.transpose();
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

  // Noise covariance accumulated over the rows (sum of each row's covariance).
  SolveMatrix accumulated_noise_covariance(const State& s, SolveScalar weight) const noexcept {
    using T = SolveScalar;
    if constexpr (!Hysteresis) {
      return weight * noise_covariance_.template cast<T>();
    } else {
      // Each split row spreads its sensor's x_1 noise as (h, 1 - h) over the heating and
      // cooling columns: entry (a, b) collects sum_rows w_a(h) w_b(h) C0[ca][cb] with the
      // linear weights w = alpha + beta h, i.e. from the moments of (1, h1, h2). Rows before
      // the first interval are counted like the others (weight / interval count).
      const Eigen::Matrix<T, direction_dim, direction_dim> m =
          (s.block_decay * s.direction_total + s.direction_block.matrix()).template cast<T>();
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
      return c;
    }
  }

  Result solve_state(const State& s) const noexcept {
    using T = SolveScalar;
    Result out;
    const Eigen::Matrix<T, columns + 1, columns + 1> a = moments(s).template cast<T>();
    const T weight = a(columns, columns);
    out.rows = Scalar(weight);
    // Fewer rows than unknowns plus projected directions cannot determine theta.
    if (s.rows < std::uint64_t(columns + basis_size)) {
      out.status = Status::insufficient_excitation;
      return out;
    }
    // Back to the documented columns (exact enough in the solve precision), so that the
    // reference's diagonal scaling and regulariser act on the same coordinates.
    const SolveMatrix scatter = documented(projected_scatter(s));
    const SolveMatrix noise = documented(accumulated_noise_covariance(s, weight));
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
    SolveMatrix whitened = llt.matrixL().solve(s_n);
    whitened = llt.matrixL().solve(whitened.transpose()).eval();
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
    parameters(out, theta, a);
    return out;
  }

  // theta -> polynomials, time constants, gain ratio, offset; sets the status.
  void parameters(Result& out, const SolveRow& theta,
                  const Eigen::Matrix<SolveScalar, columns + 1, columns + 1>& a) const noexcept {
    using T = SolveScalar;
    const T tf = T(config_.filter_time_constant);
    const int dynamic = Hysteresis ? 4 : 2 * Order;
    const T gain = affine ? theta[dynamic] : T(1);
    out.gain_ratio = Scalar(gain);
    if constexpr (affine) {
      // o = mean of theta . z over the rows, with the offsets that centring removed. In working
      // coordinates theta = [dynamic, -g, g - 1] and the offsets are T2(0) - T1(0), -T1(0)
      // (no difference of two ~400 K values).
      SolveRow working = theta;
      working[columns - 2] = -gain;
      working[columns - 1] = gain - T(1);
      const T centred_mean =
          working.dot(a.template topRightCorner<columns, 1>()) / a(columns, columns);
      out.offset = Scalar(centred_mean - gain * (T(offset2_) - T(offset1_)) -
                          (gain - T(1)) * T(offset1_));
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
  std::array<std::array<Scalar, 2>, std::size_t(ring_size)> ring_{};
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
};

// The variants the firmware and the bindings use.
template <typename Scalar, StaticModel Static = StaticModel::unit>
using SvfFirstOrder = SvfEstimator<Scalar, 1, Static>;
template <typename Scalar, StaticModel Static = StaticModel::unit>
using SvfSecondOrder = SvfEstimator<Scalar, 2, Static>;
template <typename Scalar, StaticModel Static = StaticModel::unit, int MaxHalfWindow = 128>
using SvfHysteresis = SvfEstimator<Scalar, 1, Static, true, MaxHalfWindow>;

// ECU budget (state, delay line and configuration; no heap).
static_assert(sizeof(SvfFirstOrder<float>) <= 512, "first-order float SVF grew unexpectedly");
static_assert(sizeof(SvfSecondOrder<float, StaticModel::affine>) <= 1024,
              "second-order float SVF grew unexpectedly");
static_assert(sizeof(SvfHysteresis<float, StaticModel::affine>) <= 4096,
              "hysteresis float SVF (128-sample half window) grew unexpectedly");

}  // namespace dualprobe
