// Per-interval exact discretisation of the pair model with time-varying sensor dynamics
// (e.g. time constants that follow the gas flow, design.md 1.5): the state layout and F of
// python/dualprobe/reference/kalman.py section 1, x = [g, (g'), sensor 1 stages, sensor 2
// stages], discretised for each interval by kalman_detail::discretise (kalman_discretise.hpp,
// the same routine the Kalman reconstructor uses once per mode). The loop runs without the GIL.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cmath>
#include <cstddef>
#include <string>

#include "bindings.hpp"
#include "dualprobe/kalman_discretise.hpp"

namespace py = pybind11;
using namespace pybind11::literals;

namespace {

using dualprobe_bindings::Array;

// (rows, stages) of a (N-1,) or (N-1, S) array of stage time constants, S = 1 or 2.
std::pair<std::size_t, int> stage_shape(const char* name, const Array<double>& taus) {
  if (taus.ndim() == 1) return {std::size_t(taus.shape(0)), 1};
  if (taus.ndim() == 2 && (taus.shape(1) == 1 || taus.shape(1) == 2)) {
    return {std::size_t(taus.shape(0)), int(taus.shape(1))};
  }
  throw py::value_error(std::string(name) +
                        ": need shape (N-1,) or (N-1, S) with S = 1 or 2 stage time constants");
}

template <int N>
void discretise_all(const double* taus1, int stages1, const double* taus2, int stages2,
                    std::size_t intervals, int gas_states, double ts, double* phi_out,
                    double* q_out) {
  using Matrix = Eigen::Matrix<double, N, N>;
  const int noise_index = gas_states == 2 ? 1 : 0;
  for (std::size_t k = 0; k < intervals; ++k) {
    Matrix f = Matrix::Zero();
    if (gas_states == 2) f(0, 1) = 1.0;
    int index = gas_states;
    for (int sensor = 0; sensor < 2; ++sensor) {
      const int stages = sensor == 0 ? stages1 : stages2;
      const double* taus = (sensor == 0 ? taus1 : taus2) + k * std::size_t(stages);
      int source = 0;  // the gas level feeds the first stage
      for (int j = 0; j < stages; ++j) {
        f(index, source) += 1.0 / taus[j];
        f(index, index) -= 1.0 / taus[j];
        source = index;
        ++index;
      }
    }
    const auto d = dualprobe::kalman_detail::discretise<N>(f, noise_index, ts);
    double* p = phi_out + k * std::size_t(N * N);
    double* q = q_out + k * std::size_t(N * N);
    for (int i = 0; i < N; ++i) {
      for (int j = 0; j < N; ++j) {
        p[i * N + j] = d.phi(i, j);
        q[i * N + j] = d.q_unit(i, j);
      }
    }
  }
}

py::tuple discretise_intervals(const Array<double>& taus1, const Array<double>& taus2, double ts,
                               const std::string& gas) {
  if (!(ts > 0.0) || !std::isfinite(ts)) throw py::value_error("ts must be finite and > 0");
  int gas_states = 0;
  if (gas == "rw") {
    gas_states = 1;
  } else if (gas == "irw") {
    gas_states = 2;
  } else {
    throw py::value_error("gas must be 'rw' or 'irw', got '" + gas + "'");
  }
  const auto [rows1, stages1] = stage_shape("taus1", taus1);
  const auto [rows2, stages2] = stage_shape("taus2", taus2);
  if (rows1 != rows2) throw py::value_error("taus1 and taus2 differ in their number of intervals");
  const double* p1 = taus1.data();
  const double* p2 = taus2.data();
  for (std::size_t i = 0; i < rows1 * std::size_t(stages1); ++i) {
    if (!(p1[i] > 0.0) || !std::isfinite(p1[i])) {
      throw py::value_error("taus1: time constants must be finite and > 0");
    }
  }
  for (std::size_t i = 0; i < rows2 * std::size_t(stages2); ++i) {
    if (!(p2[i] > 0.0) || !std::isfinite(p2[i])) {
      throw py::value_error("taus2: time constants must be finite and > 0");
    }
  }
  const int n = gas_states + stages1 + stages2;
  const auto shape = std::vector<py::ssize_t>{static_cast<py::ssize_t>(rows1), n, n};
  py::array_t<double> phi(shape);
  py::array_t<double> q(shape);
  double* phi_out = phi.mutable_data();
  double* q_out = q.mutable_data();
  {
    py::gil_scoped_release release;
    switch (n) {
      case 3: discretise_all<3>(p1, stages1, p2, stages2, rows1, gas_states, ts, phi_out, q_out); break;
      case 4: discretise_all<4>(p1, stages1, p2, stages2, rows1, gas_states, ts, phi_out, q_out); break;
      case 5: discretise_all<5>(p1, stages1, p2, stages2, rows1, gas_states, ts, phi_out, q_out); break;
      default: discretise_all<6>(p1, stages1, p2, stages2, rows1, gas_states, ts, phi_out, q_out); break;
    }
  }
  return py::make_tuple(phi, q);
}

}  // namespace

namespace dualprobe_bindings {

void bind_intervals(pybind11::module_& m) {
  m.def("discretise_intervals", &discretise_intervals, "taus1"_a, "taus2"_a, "ts"_a,
        "gas"_a = "rw",
        "Exact discretisation per interval of the pair model (reference/kalman.py section 1-2) "
        "with stage time constants taus1 (N-1, S1) and taus2 (N-1, S2), S = 1 or 2 (gas -> "
        "stage 0 -> stage 1): returns (phi, q_unit), each (N-1, n, n), n = 1 or 2 gas states "
        "(gas='rw' or 'irw') + S1 + S2.");
}

}  // namespace dualprobe_bindings
