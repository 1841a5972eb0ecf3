// Bindings of the streaming SVF estimator (cpp/include/dualprobe/svf_estimator.hpp).
// The C++ variants (order, static model, hysteresis) are separate types with fixed sizes; the
// Python classes SvfEstimator (double) and SvfEstimatorF (float) pick one at construction.
// NumPy arrays are read in place (matching dtype) and batch loops run without the GIL.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <variant>

#include "bindings.hpp"
#include "dualprobe/svf_estimator.hpp"

namespace py = pybind11;
using namespace pybind11::literals;

namespace {

using dualprobe_bindings::Array;
using dualprobe_bindings::checked_length;

// The host has memory to spare: the bindings accept look-ahead windows up to 1024 samples
// (the Python layer may choose up to tf/Ts, e.g. ~550 at 100 Hz); the ECU default is 128.
constexpr int kBindingMaxHalfWindow = 1024;

template <typename S>
using Variant = std::variant<
    dualprobe::SvfEstimator<S, 1, dualprobe::StaticModel::unit>,
    dualprobe::SvfEstimator<S, 1, dualprobe::StaticModel::affine>,
    dualprobe::SvfEstimator<S, 2, dualprobe::StaticModel::unit>,
    dualprobe::SvfEstimator<S, 2, dualprobe::StaticModel::affine>,
    dualprobe::SvfEstimator<S, 1, dualprobe::StaticModel::unit, true, kBindingMaxHalfWindow>,
    dualprobe::SvfEstimator<S, 1, dualprobe::StaticModel::affine, true, kBindingMaxHalfWindow>>;

struct Options {
  double ts;
  double tf;
  int order;
  std::string static_model;
  bool hysteresis;
  double sigma1;
  double sigma2;
  double forgetting;
  std::pair<int, int> windows;
  double dead_zone;
};

std::pair<int, int> parse_windows(const py::object& value, bool hysteresis) {
  if (value.is_none()) {
    if (hysteresis) {
      throw py::value_error(
          "direction_half_window is required with hysteresis=True (an int or a pair of ints; "
          "dualprobe.reference.svf.choose_direction_half_window chooses it from the data)");
    }
    return {1, 1};
  }
  if (py::isinstance<py::int_>(value)) {
    const int w = value.cast<int>();
    return {w, w};
  }
  const auto pair = value.cast<std::pair<int, int>>();
  return pair;
}

template <typename S>
std::unique_ptr<Variant<S>> make_variant(const Options& o) {
  if (o.order != 1 && o.order != 2) throw py::value_error("order must be 1 or 2");
  if (o.static_model != "unit" && o.static_model != "affine") {
    throw py::value_error("static must be 'unit' or 'affine', got '" + o.static_model + "'");
  }
  if (o.hysteresis && o.order != 1) {
    throw py::value_error("the hysteresis split is defined for order 1 only");
  }
  const bool affine = o.static_model == "affine";
  auto holder = std::make_unique<Variant<S>>();
  const int index = o.hysteresis ? 4 + int(affine) : 2 * (o.order - 1) + int(affine);
  switch (index) {
    case 0: holder->template emplace<0>(); break;
    case 1: holder->template emplace<1>(); break;
    case 2: holder->template emplace<2>(); break;
    case 3: holder->template emplace<3>(); break;
    case 4: holder->template emplace<4>(); break;
    default: holder->template emplace<5>(); break;
  }
  dualprobe::SvfConfig<S> config;
  config.sample_interval = S(o.ts);
  config.filter_time_constant = S(o.tf);
  config.sigma1 = S(o.sigma1);
  config.sigma2 = S(o.sigma2);
  config.forgetting = S(o.forgetting);
  config.direction_half_window1 = o.windows.first;
  config.direction_half_window2 = o.windows.second;
  config.dead_zone = S(o.dead_zone);
  const auto status = std::visit([&](auto& e) { return e.configure(config); }, *holder);
  if (status != dualprobe::Status::ok) {
    throw py::value_error(
        "invalid SVF configuration: need ts > 0, tf > 0 with 1e-7 <= ts/tf <= 100, sigma1, "
        "sigma2 >= 0, 0 < forgetting <= 1 and, with hysteresis, 1 <= direction_half_window <= " +
        std::to_string(kBindingMaxHalfWindow) + " and dead_zone >= 0");
  }
  return holder;
}

template <typename V>
py::list to_list(const V& v) {
  py::list out;
  for (Eigen::Index i = 0; i < v.size(); ++i) out.append(double(v[i]));
  return out;
}

template <typename S>
py::array_t<double> to_array(const Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>& m) {
  py::array_t<double> out({m.rows(), m.cols()});
  auto view = out.template mutable_unchecked<2>();
  for (Eigen::Index i = 0; i < m.rows(); ++i)
    for (Eigen::Index j = 0; j < m.cols(); ++j) view(i, j) = double(m(i, j));
  return out;
}

template <typename E>
py::dict result_dict(const E& estimator, const typename E::Result& r) {
  py::dict out("status"_a = dualprobe::to_string(r.status), "order"_a = E::order,
               "static"_a = E::affine ? "affine" : "unit", "hysteresis"_a = E::hysteresis,
               "filter_time_constant"_a = double(estimator.config().filter_time_constant),
               "theta"_a = to_list(r.theta),
               "polynomials"_a = py::make_tuple(to_list(r.polynomial1), to_list(r.polynomial2)),
               "time_constants"_a =
                   py::make_tuple(to_list(r.time_constants1), to_list(r.time_constants2)),
               "gain_ratio"_a = double(r.gain_ratio), "offset"_a = double(r.offset),
               "eigenvalues"_a = to_list(r.eigenvalues),
               "eigenvalue_ratio"_a = double(r.eigenvalue_ratio), "rows"_a = double(r.rows));
  if (E::hysteresis) {
    out["time_constants_heat"] = py::make_tuple(py::make_tuple(double(r.tau_heat1)),
                                                py::make_tuple(double(r.tau_heat2)));
    out["time_constants_cool"] = py::make_tuple(py::make_tuple(double(r.tau_cool1)),
                                                py::make_tuple(double(r.tau_cool2)));
  } else {
    out["time_constants_heat"] = py::none();
    out["time_constants_cool"] = py::none();
  }
  return out;
}

// Feeds a batch; non-finite samples are refused (skipped). Returns the number refused.
template <typename S>
std::size_t feed(Variant<S>& holder, const S* t1, const S* t2, std::size_t n) {
  return std::visit(
      [&](auto& e) {
        std::size_t refused = 0;
        for (std::size_t k = 0; k < n; ++k) {
          if (e.update(t1[k], t2[k]) != dualprobe::Status::ok) ++refused;
        }
        return refused;
      },
      holder);
}

// The Python-facing object: one variant chosen at construction.
template <typename S>
struct PySvf {
  std::unique_ptr<Variant<S>> holder;
};

template <typename S>
PySvf<S> construct(double ts, double tf, int order, const std::string& static_model,
                   bool hysteresis, double sigma1, double sigma2, double forgetting,
                   const py::object& direction_half_window, double dead_zone) {
  const Options o{ts,         tf,     order,     static_model,
                  hysteresis, sigma1, sigma2,    forgetting,
                  parse_windows(direction_half_window, hysteresis), dead_zone};
  return PySvf<S>{make_variant<S>(o)};
}

template <typename S>
py::dict solve(const Variant<S>& holder) {
  return std::visit(
      [](const auto& e) {
        using E = std::decay_t<decltype(e)>;
        typename E::Result r;
        {
          py::gil_scoped_release release;
          r = e.solve();
        }
        return result_dict(e, r);
      },
      holder);
}

template <typename S>
void bind_class(py::module_& m, const char* name, const char* scalar) {
  using Py = PySvf<S>;
  const std::string doc = std::string("Streaming SVF cross-relation estimator (") + scalar +
                          "; design.md 1.4): order 1 or 2, static model 'unit' or 'affine', "
                          "optional heating/cooling split (order 1).";
  py::class_<Py>(m, name, doc.c_str())
      .def(py::init(&construct<S>), "ts"_a, "tf"_a, "order"_a = 1, "static"_a = "unit",
           "hysteresis"_a = false, "sigma1"_a = 0.0, "sigma2"_a = 0.0, "forgetting"_a = 1.0,
           "direction_half_window"_a = py::none(), "dead_zone"_a = 2.0)
      .def(
          "update",
          [](Py& self, S t1, S t2) {
            return std::string(dualprobe::to_string(
                std::visit([&](auto& e) { return e.update(t1, t2); }, *self.holder)));
          },
          "t1"_a, "t2"_a)
      .def(
          "update_batch",
          [](Py& self, const Array<S>& t1, const Array<S>& t2) {
            const std::size_t n = checked_length<S>(t1, t2);
            const S* p1 = t1.data();
            const S* p2 = t2.data();
            std::size_t refused = 0;
            {
              py::gil_scoped_release release;
              refused = feed<S>(*self.holder, p1, p2, n);
            }
            return refused;
          },
          "t1"_a, "t2"_a, "Feed arrays; returns the number of refused (non-finite) samples.")
      .def("solve", [](const Py& self) { return solve<S>(*self.holder); })
      .def("reset", [](Py& self) { std::visit([](auto& e) { e.reset(); }, *self.holder); })
      .def_property_readonly(
          "rows",
          [](const Py& self) {
            return std::visit([](const auto& e) { return double(e.rows()); }, *self.holder);
          })
      .def_property_readonly(
          "samples",
          [](const Py& self) {
            return std::visit([](const auto& e) { return std::uint64_t(e.samples()); },
                              *self.holder);
          })
      .def_property_readonly(
          "scatter",
          [](const Py& self) {
            return std::visit(
                [](const auto& e) {
                  return to_array<S>(Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>(e.scatter()));
                },
                *self.holder);
          },
          "Projected scatter handed to GTLS.")
      .def_property_readonly(
          "noise_covariance",
          [](const Py& self) {
            return std::visit(
                [](const auto& e) {
                  return to_array<S>(
                      Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>(e.noise_covariance()));
                },
                *self.holder);
          },
          "Noise covariance of one unsplit row for the configured sigma1, sigma2.")
      .def_property_readonly(
          "nbytes",
          [](const Py& self) {
            return std::visit([](const auto& e) { return sizeof(e); }, *self.holder);
          },
          "sizeof of the C++ estimator (binding variant: 1024-sample direction window).")
      .def_property_readonly_static("max_half_window",
                                    [](const py::object&) { return kBindingMaxHalfWindow; });
}

template <typename S>
py::dict estimate(const Array<S>& t1, const Array<S>& t2, double ts, double tf, int order,
                  const std::string& static_model, bool hysteresis, double sigma1, double sigma2,
                  double forgetting, const py::object& direction_half_window, double dead_zone) {
  const std::size_t n = checked_length<S>(t1, t2);
  auto estimator = construct<S>(ts, tf, order, static_model, hysteresis, sigma1, sigma2,
                                forgetting, direction_half_window, dead_zone);
  std::size_t refused = 0;
  {
    py::gil_scoped_release release;
    refused = feed<S>(*estimator.holder, t1.data(), t2.data(), n);
  }
  py::dict out = solve<S>(*estimator.holder);
  out["refused"] = refused;
  out["precision"] = sizeof(S) == sizeof(float) ? "float32" : "float64";
  return out;
}

template <typename S>
void bind_estimate(py::module_& m, bool convert) {
  const char* doc =
      "Batch SVF estimate on the C++ core (float64 or float32 arrays run in their own "
      "precision); returns a dict with status, theta, polynomials, time_constants (per sensor, "
      "largest first), time_constants_heat/_cool (hysteresis), gain_ratio, offset (affine), "
      "eigenvalues, eigenvalue_ratio, rows, refused.";
  if (convert) {
    m.def("estimate_svf", &estimate<S>, "t1"_a, "t2"_a, "ts"_a, "tf"_a, "order"_a = 1,
          "static"_a = "unit", "hysteresis"_a = false, "sigma1"_a = 0.0, "sigma2"_a = 0.0,
          "forgetting"_a = 1.0, "direction_half_window"_a = py::none(), "dead_zone"_a = 2.0, doc);
  } else {
    m.def("estimate_svf", &estimate<S>, "t1"_a.noconvert(), "t2"_a.noconvert(), "ts"_a, "tf"_a,
          "order"_a = 1, "static"_a = "unit", "hysteresis"_a = false, "sigma1"_a = 0.0,
          "sigma2"_a = 0.0, "forgetting"_a = 1.0, "direction_half_window"_a = py::none(),
          "dead_zone"_a = 2.0, doc);
  }
}

}  // namespace

namespace dualprobe_bindings {

void bind_svf(pybind11::module_& m) {
  bind_class<double>(m, "SvfEstimator", "double");
  bind_class<float>(m, "SvfEstimatorF", "float");
  // float64 arrays, then float32 arrays, each without conversion; then anything -> float64.
  bind_estimate<double>(m, false);
  bind_estimate<float>(m, false);
  bind_estimate<double>(m, true);
}

}  // namespace dualprobe_bindings
