// Posterior variances of the offline smoother: the diagonal of the inverse of a banded
// symmetric positive definite matrix from its LAPACK Cholesky factor (dpbtrf, upper storage),
// by the Takahashi recursion on the band: Z = A^-1 restricted to the band of the factor,
//   Z(i,j) = -(1/u_ii) sum_{k=i+1}^{i+kd} u_ik Z(k,j)          (i < j <= i+kd)
//   Z(i,i) = 1/u_ii^2 - (1/u_ii) sum_{k=i+1}^{i+kd} u_ik Z(k,i)
// from the last row up; every Z(k,j) it needs lies within the band of rows already done.
// O(n kd^2) time and O(n kd) memory, versus O(n^2) for solving for columns of the inverse.
// Host-only (not in the ECU core): the smoother runs in Python on the bench or a laptop.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <algorithm>
#include <cstddef>
#include <vector>

#include "bindings.hpp"

namespace py = pybind11;

namespace {

py::array_t<double> banded_inverse_diagonal(
    const py::array_t<double, py::array::f_style | py::array::forcecast>& factor) {
  if (factor.ndim() != 2 || factor.shape(0) < 1) {
    throw py::value_error("factor must be the (kd + 1, n) upper band of a Cholesky factor");
  }
  const auto kd = static_cast<std::ptrdiff_t>(factor.shape(0)) - 1;
  const auto n = static_cast<std::ptrdiff_t>(factor.shape(1));
  py::array_t<double> diagonal(n);
  auto out = diagonal.mutable_unchecked<1>();
  auto u = factor.unchecked<2>();
  // U(i, j) for i <= j <= i + kd sits at u(kd + i - j, j)
  const auto U = [&](std::ptrdiff_t i, std::ptrdiff_t j) { return u(kd + i - j, j); };
  for (std::ptrdiff_t i = 0; i < n; ++i) {
    if (!(U(i, i) > 0.0)) throw py::value_error("factor has a non-positive diagonal entry");
  }
  {
    py::gil_scoped_release release;
    // Row i of the inverse's band reads rows i + 1 .. i + kd only: a ring of kd + 1 rows
    // (memory O(kd^2), not another band of the factor's size at recording scale).
    std::vector<double> z(static_cast<std::size_t>((kd + 1) * (kd + 1)), 0.0);
    // Z(i, j), i <= j <= i + kd, at z[(j - i) + (kd + 1) (i mod (kd + 1))]
    const auto Z = [&](std::ptrdiff_t a, std::ptrdiff_t b) -> double& {
      const std::ptrdiff_t i = std::min(a, b);
      const std::ptrdiff_t j = std::max(a, b);
      return z[static_cast<std::size_t>((j - i) + (kd + 1) * (i % (kd + 1)))];
    };
    for (std::ptrdiff_t i = n - 1; i >= 0; --i) {
      const double uii = U(i, i);
      const std::ptrdiff_t last = std::min(i + kd, n - 1);
      for (std::ptrdiff_t j = last; j > i; --j) {
        double sum = 0.0;
        for (std::ptrdiff_t k = i + 1; k <= last; ++k) sum += U(i, k) * Z(k, j);
        Z(i, j) = -sum / uii;
      }
      double sum = 0.0;
      for (std::ptrdiff_t k = i + 1; k <= last; ++k) sum += U(i, k) * Z(k, i);
      Z(i, i) = 1.0 / (uii * uii) - sum / uii;
      out(i) = Z(i, i);
    }
  }
  return diagonal;
}

}  // namespace

namespace dualprobe_bindings {

void bind_banded(py::module_& m) {
  m.def("banded_inverse_diagonal", &banded_inverse_diagonal, py::arg("factor"),
        "Diagonal of A^-1 from the upper Cholesky band of A (LAPACK dpbtrf, lower=0): the "
        "smoother's posterior variances. Takahashi recursion, O(n kd^2).");
}

}  // namespace dualprobe_bindings
