// Errors-in-variables solvers on an accumulated scatter S of rows z with the linear relation
// v^T z = 0 (v's last entry normalised to -1). All fixed size, no heap.
//   ls:   noise only in the last column (ordinary least squares on the normal equations);
//   tls:  equal white noise in every column (smallest eigenvector of S);
//   gtls: noise covariance C (smallest generalised eigenvector of S v = mu C v), the
//         consistent estimator when every column is noisy (Hung et al. 2005).
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <cmath>
#include <limits>

#include "dualprobe/status.hpp"

namespace dualprobe {

enum class Method : int { ls = 0, tls = 1, gtls = 2 };

template <typename Scalar, int N>
struct EivSolution {
  Status status{Status::not_ready};
  Eigen::Matrix<Scalar, N - 1, 1> theta{Eigen::Matrix<Scalar, N - 1, 1>::Zero()};
  // Smallest and second-smallest (generalised) eigenvalues; their ratio says whether the
  // null space is one-dimensional, i.e. whether theta is identifiable at all.
  Scalar smallest{0};
  Scalar second_smallest{0};
};

namespace detail {

template <typename Scalar>
constexpr Scalar rank_tolerance() noexcept {
  // A second eigenvalue this small relative to the largest means a two-dimensional null
  // space: the data cannot single out one relation.
  return std::numeric_limits<Scalar>::epsilon() * Scalar(64);
}

template <typename Scalar, int N>
EivSolution<Scalar, N> from_null_vector(const Eigen::Matrix<Scalar, N, 1>& v, Scalar smallest,
                                        Scalar second, Scalar largest) noexcept {
  EivSolution<Scalar, N> out;
  out.smallest = smallest;
  out.second_smallest = second;
  if (!(largest > Scalar(0)) || !(second > rank_tolerance<Scalar>() * largest)) {
    out.status = Status::insufficient_excitation;
    return out;
  }
  const Scalar last = v[N - 1];
  if (!(std::abs(last) > std::numeric_limits<Scalar>::epsilon() * v.norm())) {
    out.status = Status::infeasible;
    return out;
  }
  out.theta = -v.template head<N - 1>() / last;
  out.status = out.theta.allFinite() ? Status::ok : Status::infeasible;
  return out;
}

}  // namespace detail

template <typename Scalar, int N>
EivSolution<Scalar, N> solve_ls(const Eigen::Matrix<Scalar, N, N>& scatter) noexcept {
  EivSolution<Scalar, N> out;
  const auto normal = scatter.template topLeftCorner<N - 1, N - 1>();
  const Scalar scale = normal.diagonal().maxCoeff();
  if (!(scale > Scalar(0))) {
    out.status = Status::insufficient_excitation;
    return out;
  }
  Eigen::LDLT<Eigen::Matrix<Scalar, N - 1, N - 1>> ldlt(normal);
  const auto d = ldlt.vectorD();
  if (ldlt.info() != Eigen::Success || !(d.minCoeff() > detail::rank_tolerance<Scalar>() * scale)) {
    out.status = Status::insufficient_excitation;
    return out;
  }
  out.theta = ldlt.solve(scatter.template topRightCorner<N - 1, 1>());
  out.status = out.theta.allFinite() ? Status::ok : Status::infeasible;
  return out;
}

template <typename Scalar, int N>
EivSolution<Scalar, N> solve_tls(const Eigen::Matrix<Scalar, N, N>& scatter) noexcept {
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix<Scalar, N, N>> eig(scatter);
  if (eig.info() != Eigen::Success) {
    EivSolution<Scalar, N> out;
    out.status = Status::insufficient_excitation;
    return out;
  }
  const auto& values = eig.eigenvalues();  // ascending
  return detail::from_null_vector<Scalar, N>(eig.eigenvectors().col(0), values[0], values[1],
                                             values[N - 1]);
}

// C must be symmetric positive definite. The problem is whitened with C = L L^T so that
// the ordinary symmetric eigensolver applies: (L^-1 S L^-T) u = mu u, v = L^-T u.
template <typename Scalar, int N>
EivSolution<Scalar, N> solve_gtls(const Eigen::Matrix<Scalar, N, N>& scatter,
                                  const Eigen::Matrix<Scalar, N, N>& noise_covariance) noexcept {
  using Matrix = Eigen::Matrix<Scalar, N, N>;
  EivSolution<Scalar, N> out;
  Eigen::LLT<Matrix> llt(noise_covariance);
  if (llt.info() != Eigen::Success) {
    out.status = Status::invalid_argument;
    return out;
  }
  // Column by column: a matrix right-hand side instantiates Eigen's blocked triangular solver,
  // which references malloc/free and thread-safe statics (fails the firmware's heap guard).
  Matrix half;
  for (int j = 0; j < N; ++j) half.col(j) = llt.matrixL().solve(scatter.col(j));
  const Matrix half_t = half.transpose();
  Matrix whitened;
  for (int j = 0; j < N; ++j) whitened.col(j) = llt.matrixL().solve(half_t.col(j));
  // Symmetrise: rounding in the two triangular solves breaks exact symmetry.
  const Matrix symmetric = Scalar(0.5) * (whitened + whitened.transpose());
  Eigen::SelfAdjointEigenSolver<Matrix> eig(symmetric);
  if (eig.info() != Eigen::Success) {
    out.status = Status::insufficient_excitation;
    return out;
  }
  const Eigen::Matrix<Scalar, N, 1> v = llt.matrixU().solve(eig.eigenvectors().col(0));
  const auto& values = eig.eigenvalues();
  return detail::from_null_vector<Scalar, N>(v, values[0], values[1], values[N - 1]);
}

}  // namespace dualprobe
