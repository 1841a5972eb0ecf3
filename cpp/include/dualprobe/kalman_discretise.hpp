// Exact discretisation of a linear time-invariant model driven by white noise on one state
// (the Van Loan result, docs: python/dualprobe/reference/kalman.py section 2):
//   Phi = expm(F Ts),   Qunit = int_0^Ts expm(F s) e_L e_L^T expm(F s)^T ds.
// Computed here without the 2n x 2n Van Loan matrix: scaling by 2^-s so that ||F h|| <= 1/4,
// Taylor series of degree 16 for Phi(h) and for Q(h) (a sum of outer products of the vectors
// (F h)^i e_L / i!, no cancellation), then s doublings
//   Q(2h) = Q(h) + Phi(h) Q(h) Phi(h)^T,   Phi(2h) = Phi(h)^2,
// each a sum of positive semi-definite terms. Truncation error <= 2^-17/17! ~ 2e-20 relative;
// the doublings add a few ulp each. n x n fixed-size doubles only (N = 6: under 2 KiB of stack,
// which is why neither Eigen's MatrixFunctions nor a Pade solve on the 2n Van Loan matrix is
// used: the former references the heap through its LU and products, the latter needs ~9 KiB).
// Products are lazy (coefficient-based), so no GEMM kernel and no heap symbol is pulled in.
#pragma once

#include <Eigen/Core>
#include <cmath>

namespace dualprobe {
namespace kalman_detail {

constexpr int kTaylorDegree = 16;
constexpr double kScaledNorm = 0.25;
constexpr int kMaxDoublings = 1100;  // ||F Ts|| up to ~1e330: every finite input terminates

template <int N>
struct Discretisation {
  Eigen::Matrix<double, N, N> phi;
  Eigen::Matrix<double, N, N> q_unit;
};

// F: continuous-time matrix (only the leading n x n block is used, the rest must be zero),
// noise_index: the state the unit-intensity white noise drives, ts > 0.
template <int N>
Discretisation<N> discretise(const Eigen::Matrix<double, N, N>& f, int noise_index,
                             double ts) noexcept {
  using Matrix = Eigen::Matrix<double, N, N>;
  using Vector = Eigen::Matrix<double, N, 1>;
  const double norm = (f * ts).cwiseAbs().rowwise().sum().maxCoeff();  // infinity norm
  int doublings = 0;
  double h = ts;
  double scaled = norm;
  while (scaled > kScaledNorm && doublings < kMaxDoublings) {
    h *= 0.5;
    scaled *= 0.5;
    ++doublings;
  }
  const Matrix a = f * h;
  // w[i] = a^i e_L / i!;  Phi(h) = sum a^i / i!
  Vector w[kTaylorDegree + 1];
  w[0].setZero();
  w[0][noise_index] = 1.0;
  Matrix term = Matrix::Identity();
  Discretisation<N> out;
  out.phi = Matrix::Identity();
  for (int i = 1; i <= kTaylorDegree; ++i) {
    term = (term.lazyProduct(a) / double(i)).eval();
    out.phi += term;
    w[i] = a.lazyProduct(w[i - 1]) / double(i);
  }
  // Q(h) = int_0^h (sum_i s^i F^i e_L / i!)(...)^T ds = h sum_{i,j} w_i w_j^T / (i + j + 1)
  out.q_unit.setZero();
  for (int i = 0; i <= kTaylorDegree; ++i) {
    for (int j = 0; i + j <= kTaylorDegree; ++j) {
      out.q_unit += (h / double(i + j + 1)) * w[i] * w[j].transpose();
    }
  }
  for (int r = 0; r < doublings; ++r) {
    const Matrix left = out.phi.lazyProduct(out.q_unit);
    out.q_unit += left.lazyProduct(out.phi.transpose());
    out.phi = out.phi.lazyProduct(out.phi).eval();
  }
  out.q_unit = (0.5 * (out.q_unit + out.q_unit.transpose())).eval();
  return out;
}

}  // namespace kalman_detail
}  // namespace dualprobe
