// Thin pybind11 bindings of the C++ core: NumPy arrays in without copying (matching dtype),
// batch loops run with the GIL released, results as plain dicts.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstddef>
#include <stdexcept>
#include <string>

#include "bindings.hpp"
#include "dualprobe/dualprobe.hpp"

namespace py = pybind11;
using namespace pybind11::literals;

namespace {

using dualprobe_bindings::Array;
using dualprobe_bindings::checked_length;

dualprobe::Method parse_method(const std::string& name) {
  if (name == "ls") return dualprobe::Method::ls;
  if (name == "tls") return dualprobe::Method::tls;
  if (name == "gtls") return dualprobe::Method::gtls;
  throw py::value_error("method must be 'ls', 'tls' or 'gtls', got '" + name + "'");
}

template <typename S>
dualprobe::DifferenceConfig<S> make_config(double ts, const std::string& method, double sigma1,
                                           double sigma2, double forgetting) {
  dualprobe::DifferenceConfig<S> config;
  config.sample_interval = S(ts);
  config.method = parse_method(method);
  config.sigma1 = S(sigma1);
  config.sigma2 = S(sigma2);
  config.forgetting = S(forgetting);
  if (!config.valid()) {
    throw py::value_error(
        "invalid estimator configuration: need ts > 0, 0 < forgetting <= 1 and, for gtls, "
        "sigma1 > 0 and sigma2 > 0");
  }
  return config;
}

template <typename S>
py::dict result_dict(const dualprobe::DifferenceResult<S>& r) {
  return py::dict("status"_a = dualprobe::to_string(r.status), "beta"_a = double(r.beta),
                  "b1"_a = double(r.b1), "b2"_a = double(r.b2), "tau1"_a = double(r.tau1),
                  "tau2"_a = double(r.tau2), "eigenvalue_ratio"_a = double(r.eigenvalue_ratio));
}

// Feeds a batch; a non-finite sample is refused and breaks the chain of differences so no
// difference spans the gap (DifferenceEstimator::update_block). Returns the refused count.
template <typename S>
std::size_t feed_batch(dualprobe::DifferenceEstimator<S>& estimator, const S* t1, const S* t2,
                       std::size_t n) {
  return estimator.update_block(t1, t2, n);
}

template <typename S>
void bind_estimator(py::module_& m, const char* name) {
  using Estimator = dualprobe::DifferenceEstimator<S>;
  py::class_<Estimator>(m, name,
                        "Streaming difference-equation dual-sensor estimator (paper eqs. 10-12).")
      .def(py::init([](double ts, const std::string& method, double sigma1, double sigma2,
                       double forgetting) {
             Estimator estimator;
             estimator.configure(make_config<S>(ts, method, sigma1, sigma2, forgetting));
             return estimator;
           }),
           "ts"_a, "method"_a = "gtls", "sigma1"_a = 0.0, "sigma2"_a = 0.0, "forgetting"_a = 1.0)
      .def(
          "update",
          [](Estimator& e, S t1, S t2) { return std::string(dualprobe::to_string(e.update(t1, t2))); },
          "t1"_a, "t2"_a)
      .def(
          "update_batch",
          [](Estimator& e, const Array<S>& t1, const Array<S>& t2) {
            const std::size_t n = checked_length<S>(t1, t2);
            const S* p1 = t1.data();
            const S* p2 = t2.data();
            std::size_t refused = 0;
            {
              py::gil_scoped_release release;
              refused = feed_batch(e, p1, p2, n);
            }
            return refused;
          },
          "t1"_a, "t2"_a, "Feed arrays; returns the number of refused (non-finite) samples.")
      .def("solve", [](const Estimator& e) { return result_dict(e.solve()); })
      .def("reset", &Estimator::reset)
      .def("break_chain", &Estimator::break_chain)
      .def_property_readonly("rows", [](const Estimator& e) { return double(e.rows()); })
      .def_property_readonly("scatter", [](const Estimator& e) {
        py::array_t<double> out({3, 3});
        auto view = out.mutable_unchecked<2>();
        const auto s = e.scatter();
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) view(i, j) = double(s(i, j));
        return out;
      });
}

template <typename S>
py::dict estimate_difference(const Array<S>& t1, const Array<S>& t2, double ts,
                             const std::string& method, double sigma1, double sigma2,
                             double forgetting) {
  const std::size_t n = checked_length<S>(t1, t2);
  dualprobe::DifferenceEstimator<S> estimator;
  estimator.configure(make_config<S>(ts, method, sigma1, sigma2, forgetting));
  dualprobe::DifferenceResult<S> result;
  std::size_t refused = 0;
  {
    py::gil_scoped_release release;
    refused = feed_batch(estimator, t1.data(), t2.data(), n);
    result = estimator.solve();
  }
  py::dict out = result_dict(result);
  out["refused"] = refused;
  return out;
}

template <typename S>
Array<S> reconstruct_inverse(const Array<S>& temps, double tau, double ts) {
  if (temps.ndim() != 1) throw py::value_error("signal must be one-dimensional");
  const std::size_t n = static_cast<std::size_t>(temps.shape(0));
  Array<S> out(static_cast<py::ssize_t>(n));
  S* dst = out.mutable_data();
  dualprobe::Status status;
  {
    py::gil_scoped_release release;
    status = dualprobe::reconstruct_inverse<S>(temps.data(), n, S(tau), S(ts), dst);
  }
  if (status != dualprobe::Status::ok) throw py::value_error("need tau > 0 and ts > 0");
  return out;
}

template <typename S>
Array<S> simulate_hysteretic(const Array<S>& gas, double ts, double tau_heat, double tau_cool,
                             double initial) {
  if (gas.ndim() != 1) throw py::value_error("gas temperature must be one-dimensional");
  const std::size_t n = static_cast<std::size_t>(gas.shape(0));
  Array<S> out(static_cast<py::ssize_t>(n));
  S* dst = out.mutable_data();
  dualprobe::Status status;
  {
    py::gil_scoped_release release;
    status = dualprobe::simulate_hysteretic_first_order<S>(gas.data(), n, S(ts), S(tau_heat),
                                                           S(tau_cool), S(initial), dst);
  }
  if (status != dualprobe::Status::ok) {
    throw py::value_error("need ts > 0, tau_heat > 0, tau_cool > 0 and a finite initial value");
  }
  return out;
}

template <typename S>
void bind_functions(py::module_& m) {
  m.def("estimate_difference", &estimate_difference<S>, "t1"_a.noconvert(), "t2"_a.noconvert(),
        "ts"_a, "method"_a = "gtls", "sigma1"_a = 0.0, "sigma2"_a = 0.0, "forgetting"_a = 1.0,
        "Batch difference-equation estimate (C++ core); returns a dict with status, beta, b1, "
        "b2, tau1, tau2, eigenvalue_ratio, refused.");
  m.def("reconstruct_inverse", &reconstruct_inverse<S>, "temps"_a.noconvert(), "tau"_a, "ts"_a,
        "Exact first-order inverse: out[k-1] = Tg(k-1); out[-1] = nan.");
  m.def("simulate_hysteretic_first_order", &simulate_hysteretic<S>, "tg"_a.noconvert(), "ts"_a,
        "tau_heat"_a, "tau_cool"_a, "initial"_a,
        "First-order sensor with direction-dependent time constant, gas held over each sample.");
}

}  // namespace

PYBIND11_MODULE(_core, m) {
  m.doc() = "dualprobe C++ core (fixed memory, float and double)";
  bind_estimator<double>(m, "DifferenceEstimator");
  bind_estimator<float>(m, "DifferenceEstimatorF");
  // float64 first, then float32; each only for its own dtype, then float64 with conversion.
  bind_functions<double>(m);
  bind_functions<float>(m);
  m.def(
      "estimate_difference",
      [](const Array<double>& t1, const Array<double>& t2, double ts, const std::string& method,
         double sigma1, double sigma2, double forgetting) {
        return estimate_difference<double>(t1, t2, ts, method, sigma1, sigma2, forgetting);
      },
      "t1"_a, "t2"_a, "ts"_a, "method"_a = "gtls", "sigma1"_a = 0.0, "sigma2"_a = 0.0,
      "forgetting"_a = 1.0);
  m.def(
      "reconstruct_inverse",
      [](const Array<double>& temps, double tau, double ts) {
        return reconstruct_inverse<double>(temps, tau, ts);
      },
      "temps"_a, "tau"_a, "ts"_a);
  m.def(
      "simulate_hysteretic_first_order",
      [](const Array<double>& gas, double ts, double tau_heat, double tau_cool, double initial) {
        return simulate_hysteretic<double>(gas, ts, tau_heat, tau_cool, initial);
      },
      "tg"_a, "ts"_a, "tau_heat"_a, "tau_cool"_a, "initial"_a);
  dualprobe_bindings::bind_svf(m);
  dualprobe_bindings::bind_kalman(m);
  dualprobe_bindings::bind_svf_filter(m);
  dualprobe_bindings::bind_banded(m);
  dualprobe_bindings::bind_intervals(m);
  dualprobe_bindings::bind_varying(m);
}
