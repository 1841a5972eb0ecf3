// The state-variable filter of the SVF estimator (design.md 1.4): F(s) = 1/(1 + tf s)^M as a
// cascade of M equal lags v_0 = G u, v_j = G v_{j-1}, G = 1/(1 + tf s), discretised exactly in
// closed form (no matrix exponential), h = Ts/tf, P(a, x) the regularised lower incomplete
// gamma function:
//   FOH: v(k+1) = phi v(k) + ga u(k) + gb u(k+1),   ZOH: gb = 0, ga_j = P(j+1, h),
//   phi[j][i] = exp(-h) h^(j-i)/(j-i)!  (lower triangular Toeplitz),
//   FOH: ga_j = (j+1) P(j+2, h)/h,  gb_j = P(j+1, h) - ga_j.
// Scaled filtered derivatives x_j = (tf s)^j F u are binomial differences of the last states.
// The stationary state covariance under unit white input noise solves a discrete Lyapunov
// equation, computed here by doubling on fixed-size matrices (no heap, no matrix exponential).
//
// Configuration-time arithmetic is done in double for both scalar types: it runs once, and the
// float estimator then starts from correctly rounded coefficients.
#pragma once

#include <Eigen/Core>
#include <cmath>

namespace dualprobe {
namespace svf_detail {

// Regularised lower incomplete gamma P(n, x) for integer n >= 1, x >= 0: series below n + 1
// (no cancellation for small x, where the FOH weights are tiny), else 1 - Q with the finite
// sum Q = exp(-x) sum_{k<n} x^k/k! (Q <= ~1/2 there, so 1 - Q keeps full relative accuracy).
inline double regularised_lower_gamma(int n, double x) noexcept {
  if (!(x > 0.0)) return 0.0;
  if (x < double(n) + 1.0) {
    double term = 1.0;
    double sum = 1.0;
    for (int k = 1; k < 200; ++k) {
      term *= x / double(n + k);
      sum += term;
      if (term < 1e-17 * sum) break;
    }
    double prefactor = std::exp(-x);
    for (int k = 1; k <= n; ++k) prefactor *= x / double(k);
    return prefactor * sum;
  }
  double term = std::exp(-x);
  double q = term;
  for (int k = 1; k < n; ++k) {
    term *= x / double(k);
    q += term;
  }
  return 1.0 - q;
}

// Binomial coefficient for the small orders used here.
constexpr double binomial(int n, int k) noexcept {
  double out = 1.0;
  for (int i = 1; i <= k; ++i) out = out * double(n - k + i) / double(i);
  return out;
}

}  // namespace svf_detail

// Exact discretisation of the M-fold lag cascade, in double (configuration time).
template <int M>
struct SvfDiscretisation {
  static_assert(M >= 1 && M <= 4, "cascade length out of the supported range");
  using Matrix = Eigen::Matrix<double, M, M>;
  using Vector = Eigen::Matrix<double, M, 1>;

  Matrix phi{Matrix::Zero()};
  Vector ga{Vector::Zero()};
  Vector gb{Vector::Zero()};
  // Stationary covariance of v for unit-variance white samples u (FOH: the input noise
  // enters through ga and gb).
  Matrix state_covariance{Matrix::Zero()};

  // h = Ts/tf > 0 (checked by the caller).
  static SvfDiscretisation make(double h, bool first_order_hold) noexcept {
    SvfDiscretisation d;
    const double decay = std::exp(-h);
    double power = 1.0;  // h^l / l!
    for (int l = 0; l < M; ++l) {
      for (int j = l; j < M; ++j) d.phi(j, j - l) = decay * power;
      power *= h / double(l + 1);
    }
    for (int j = 0; j < M; ++j) {
      const double gamma0 = svf_detail::regularised_lower_gamma(j + 1, h);
      if (first_order_hold) {
        const double ramp = double(j + 1) * svf_detail::regularised_lower_gamma(j + 2, h) / h;
        d.ga[j] = ramp;
        d.gb[j] = gamma0 - ramp;
      } else {
        d.ga[j] = gamma0;
        d.gb[j] = 0.0;
      }
    }
    // w(k) = v(k) - gb u(k) obeys w(k+1) = phi w(k) + q u(k), q = phi gb + ga, independent of
    // u(k); so cov(v) = P_w + gb gb^T with P_w = phi P_w phi^T + q q^T. Doubling:
    // P <- P + A P A^T, A <- A^2 sums phi^i q q^T phi^iT over i < 2^steps.
    const Vector q = d.phi * d.gb + d.ga;
    Matrix p = q * q.transpose();
    Matrix a = d.phi;
    for (int step = 0; step < 64; ++step) {
      p += a * p * a.transpose();
      a = (a * a).eval();
      // The next term is below ||A||^2 ||P||: stop once that is far below double rounding.
      const double size = a.cwiseAbs().maxCoeff();
      if (size * size < 1e-20) break;
    }
    d.state_covariance = p + d.gb * d.gb.transpose();
    d.state_covariance = 0.5 * (d.state_covariance + d.state_covariance.transpose()).eval();
    return d;
  }

  // Row j of the derivative map L: x_j = (tf s)^j F u = sum_i (-1)^i C(j, i) v_{M-1-j+i}
  // (since (tf s) v_i = v_{i-1} - v_i).
  static Eigen::Matrix<double, M, M> derivative_map() noexcept {
    Eigen::Matrix<double, M, M> l = Eigen::Matrix<double, M, M>::Zero();
    for (int j = 0; j < M; ++j) {
      for (int i = 0; i <= j; ++i) {
        l(j, M - 1 - j + i) = ((i % 2) ? -1.0 : 1.0) * svf_detail::binomial(j, i);
      }
    }
    return l;
  }
};

// The cascade as run per sample, in the working precision. The update is written in delta
// form, v += (phi - I) v + ga u(k) + gb u(k+1), with the diagonal of phi - I as expm1(-h): the
// increment is O(h |v|) and so is its rounding, instead of O(|v|) per step (matters in float,
// where the state follows a signal of a few hundred kelvin with h ~ 0.01).
template <typename Scalar, int M>
struct SvfCascade {
  using Vector = Eigen::Matrix<Scalar, M, 1>;

  Scalar diagonal_step{0};                     // expm1(-h) = phi_jj - 1
  Vector off_diagonal{Vector::Zero()};         // off_diagonal[l] = phi[j][j-l], l >= 1
  Vector ga{Vector::Zero()};
  Vector gb{Vector::Zero()};
  bool first_order_hold{true};

  void set(double h, bool foh) noexcept {
    const auto d = SvfDiscretisation<M>::make(h, foh);
    diagonal_step = Scalar(std::expm1(-h));
    for (int l = 0; l < M; ++l) off_diagonal[l] = Scalar(l == 0 ? 0.0 : d.phi(l, 0));
    ga = d.ga.template cast<Scalar>();
    gb = d.gb.template cast<Scalar>();
    first_order_hold = foh;
  }

  // v <- phi v + ga u_previous + gb u_current (ZOH: gb = 0, u_current unused).
  void step(Vector& v, Scalar u_previous, Scalar u_current) const noexcept {
    for (int j = M - 1; j >= 0; --j) {  // descending: the lower states still hold v(k)
      Scalar increment = diagonal_step * v[j] + ga[j] * u_previous;
      if (first_order_hold) increment += gb[j] * u_current;
      for (int i = 0; i < j; ++i) increment += off_diagonal[j - i] * v[i];
      v[j] += increment;
    }
  }

  // Free response basis step: b <- phi b (exact delta form as above, no input).
  void propagate(Vector& b) const noexcept { step(b, Scalar(0), Scalar(0)); }
};

// Scaled derivatives x_0..x_{D-1} of the last cascade state (D <= M).
template <int D, typename Scalar, int M>
Eigen::Matrix<Scalar, D, 1> svf_derivatives(const Eigen::Matrix<Scalar, M, 1>& v) noexcept {
  static_assert(D >= 1 && D <= M, "derivative order exceeds the cascade");
  Eigen::Matrix<Scalar, D, 1> x;
  x[0] = v[M - 1];
  if constexpr (D >= 2) x[1] = v[M - 2] - v[M - 1];
  if constexpr (D >= 3) x[2] = v[M - 3] - Scalar(2) * v[M - 2] + v[M - 1];
  if constexpr (D >= 4) x[3] = v[M - 4] - Scalar(3) * v[M - 3] + Scalar(3) * v[M - 2] - v[M - 1];
  return x;
}

}  // namespace dualprobe
