// Bindings of the SVF's filter itself (cpp/include/dualprobe/svf_filter.hpp), for the
// estimation's offline pieces that filter other signals than the estimator's own columns: the
// time-knot columns of the tracker and the slope statistics behind the direction windows
// (python/dualprobe/estimation/). The same cascade and discretisation as the estimator.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstddef>
#include <string>

#include "bindings.hpp"
#include "dualprobe/svf_filter.hpp"

namespace py = pybind11;
using namespace pybind11::literals;

namespace {

template <int M>
py::array_t<double> filter_rows(const py::array_t<double, py::array::c_style | py::array::forcecast>& u,
                                double h, bool foh) {
  if (u.ndim() != 1 && u.ndim() != 2) throw py::value_error("u must be 1-D or 2-D (rows, samples)");
  const py::ssize_t rows = u.ndim() == 2 ? u.shape(0) : 1;
  const py::ssize_t n = u.ndim() == 2 ? u.shape(1) : u.shape(0);
  py::array_t<double> out({rows, static_cast<py::ssize_t>(M), n});
  const double* in = u.data();
  double* dst = out.mutable_data();
  {
    py::gil_scoped_release release;
    dualprobe::SvfCascade<double, M> cascade;
    cascade.set(h, foh);
    for (py::ssize_t r = 0; r < rows; ++r) {
      const double* x = in + r * n;
      double* y = dst + r * M * n;
      Eigen::Matrix<double, M, 1> v = Eigen::Matrix<double, M, 1>::Zero();  // at rest
      for (py::ssize_t k = 0; k < n; ++k) {
        if (k > 0) cascade.step(v, x[k - 1], x[k]);
        const auto d = dualprobe::svf_derivatives<M>(v);
        for (int j = 0; j < M; ++j) y[j * n + k] = d[j];
      }
    }
  }
  return out;
}

py::array_t<double> svf_filter(const py::array_t<double, py::array::c_style | py::array::forcecast>& u,
                               double ts, double tf, int m, const std::string& hold) {
  if (!(ts > 0.0) || !(tf > 0.0)) throw py::value_error("need ts > 0 and tf > 0");
  if (hold != "foh" && hold != "zoh") throw py::value_error("hold must be 'foh' or 'zoh'");
  const double h = ts / tf;
  const bool foh = hold == "foh";
  switch (m) {
    case 1: return filter_rows<1>(u, h, foh);
    case 2: return filter_rows<2>(u, h, foh);
    case 3: return filter_rows<3>(u, h, foh);
    case 4: return filter_rows<4>(u, h, foh);
    default: throw py::value_error("m must be 1..4");
  }
}

template <int M>
py::dict discretisation(double h, bool foh) {
  const auto d = dualprobe::SvfDiscretisation<M>::make(h, foh);
  const auto l = dualprobe::SvfDiscretisation<M>::derivative_map();
  const auto to = [](const auto& matrix) {
    py::array_t<double> a({matrix.rows(), matrix.cols()});
    auto v = a.template mutable_unchecked<2>();
    for (Eigen::Index i = 0; i < matrix.rows(); ++i)
      for (Eigen::Index j = 0; j < matrix.cols(); ++j) v(i, j) = matrix(i, j);
    return a;
  };
  return py::dict("phi"_a = to(d.phi), "ga"_a = to(d.ga), "gb"_a = to(d.gb),
                  "derivative_map"_a = to(l), "state_covariance"_a = to(d.state_covariance));
}

py::dict svf_discretisation(double ts, double tf, int m, const std::string& hold) {
  if (!(ts > 0.0) || !(tf > 0.0)) throw py::value_error("need ts > 0 and tf > 0");
  if (hold != "foh" && hold != "zoh") throw py::value_error("hold must be 'foh' or 'zoh'");
  const double h = ts / tf;
  const bool foh = hold == "foh";
  switch (m) {
    case 1: return discretisation<1>(h, foh);
    case 2: return discretisation<2>(h, foh);
    case 3: return discretisation<3>(h, foh);
    case 4: return discretisation<4>(h, foh);
    default: throw py::value_error("m must be 1..4");
  }
}

}  // namespace

namespace dualprobe_bindings {

void bind_svf_filter(py::module_& m) {
  m.def("svf_filter", &svf_filter, "u"_a, "ts"_a, "tf"_a, "m"_a, "hold"_a = "foh",
        "The SVF's cascade F = 1/(1 + tf s)^m on each row of u (1-D or (rows, samples)), "
        "starting at rest: (rows, m, samples) of the scaled derivatives x_j = (tf s)^j F u.");
  m.def("svf_discretisation", &svf_discretisation, "ts"_a, "tf"_a, "m"_a, "hold"_a = "foh",
        "Exact discretisation of the SVF cascade: phi, ga, gb, derivative_map and the "
        "stationary state covariance for unit white input (svf_filter.hpp).");
}

}  // namespace dualprobe_bindings
