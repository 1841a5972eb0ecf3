// Symmetric scatter (sum of outer products) of fixed dimension N with exponential forgetting.
// Only the upper triangle is stored and updated: that halves the per-sample work and keeps the
// accumulated matrix exactly symmetric, which matters for long float runs.
#pragma once

#include <Eigen/Core>

namespace dualprobe {

template <typename Scalar, int N>
class SymmetricScatter {
 public:
  static constexpr int dimension = N;
  static constexpr int packed_size = N * (N + 1) / 2;
  using Vector = Eigen::Matrix<Scalar, N, 1>;
  using Matrix = Eigen::Matrix<Scalar, N, N>;

  void reset() noexcept {
    packed_.setZero();
    weight_ = Scalar(0);
  }

  // S <- lambda S + z z^T ; weight <- lambda weight + 1 (the effective number of rows).
  void add(const Vector& z, Scalar lambda) noexcept {
    int index = 0;
    // Fully unrolled: at -O2 GCC keeps the triangular loop nest (~2x the M4F instructions).
#pragma GCC unroll 16
    for (int row = 0; row < N; ++row) {
#pragma GCC unroll 16
      for (int col = row; col < N; ++col, ++index) {
        packed_[index] = lambda * packed_[index] + z[row] * z[col];
      }
    }
    weight_ = lambda * weight_ + Scalar(1);
  }

  // Without forgetting the multiply by lambda is skipped (the ECU's common case).
  void add(const Vector& z) noexcept {
    int index = 0;
    // Fully unrolled: at -O2 GCC keeps the triangular loop nest (~2x the M4F instructions).
#pragma GCC unroll 16
    for (int row = 0; row < N; ++row) {
#pragma GCC unroll 16
      for (int col = row; col < N; ++col, ++index) {
        packed_[index] += z[row] * z[col];
      }
    }
    weight_ += Scalar(1);
  }

  Matrix matrix() const noexcept {
    Matrix full;
    int index = 0;
    for (int row = 0; row < N; ++row) {
      for (int col = row; col < N; ++col, ++index) {
        full(row, col) = packed_[index];
        full(col, row) = packed_[index];
      }
    }
    return full;
  }

  Scalar weight() const noexcept { return weight_; }

  // Direct access for block updates that keep the entries in registers (row-major upper
  // triangle: (0,0), (0,1), ..., (0,N-1), (1,1), ...); add_weight accounts for their rows.
  Eigen::Matrix<Scalar, packed_size, 1>& packed() noexcept { return packed_; }
  void add_weight(Scalar rows) noexcept { weight_ += rows; }

 private:
  Eigen::Matrix<Scalar, packed_size, 1> packed_{Eigen::Matrix<Scalar, packed_size, 1>::Zero()};
  Scalar weight_{0};
};

}  // namespace dualprobe
