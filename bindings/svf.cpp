// Bindings of the streaming SVF estimator (cpp/include/dualprobe/svf_estimator.hpp), with and
// without a flow schedule (design.md 1.4, 1.5). The C++ variants (order, static model,
// hysteresis, schedule basis) are separate types with fixed sizes; the Python classes
// SvfEstimator (double) and SvfEstimatorF (float) pick one at construction (svf_handle.hpp).
// NumPy arrays are read in place (matching dtype) and batch loops run without the GIL.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "bindings.hpp"
#include "svf_handle.hpp"

namespace py = pybind11;
using namespace pybind11::literals;

namespace {

using dualprobe_bindings::Array;
using dualprobe_bindings::checked_length;
using dualprobe_bindings::svf::Batch;
using dualprobe_bindings::svf::Handle;
using dualprobe_bindings::svf::kMaxBasis;
using dualprobe_bindings::svf::kMaxHalfWindow;
using dualprobe_bindings::svf::make_model;
using dualprobe_bindings::svf::Options;

std::pair<int, int> parse_windows(const py::object& value, bool hysteresis, bool required) {
  if (value.is_none()) {
    if (hysteresis && required) {
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
  return value.cast<std::pair<int, int>>();
}

void check_variant(const Options& o) {
  if (o.order != 1 && o.order != 2) throw py::value_error("order must be 1 or 2");
  if (o.static_model != "unit" && o.static_model != "affine") {
    throw py::value_error("static must be 'unit' or 'affine', got '" + o.static_model + "'");
  }
  if (o.hysteresis && o.order != 1) {
    throw py::value_error("the hysteresis split is defined for order 1 only");
  }
  if (o.basis < 0 || o.basis > kMaxBasis) {
    throw py::value_error("basis: 0 (no schedule) to " + std::to_string(kMaxBasis) +
                          " schedule weights per sample, got " + std::to_string(o.basis));
  }
  if (o.basis > 1 && (o.static_model == "affine" || o.hysteresis)) {
    throw py::value_error(
        "the affine static model and the hysteresis split take a single schedule psi (basis 1)");
  }
}

template <typename S>
std::unique_ptr<Handle<S>> make_handle(const Options& o) {
  using dualprobe::StaticModel;
  check_variant(o);
  if (o.basis >= 1) {
    return o.order == 1 ? dualprobe_bindings::svf::make_scheduled_order1<S>(o)
                        : dualprobe_bindings::svf::make_scheduled_order2<S>(o);
  }
  const bool affine = o.static_model == "affine";
  if (o.hysteresis) {
    if (affine) {
      return make_model<dualprobe::SvfEstimator<S, 1, StaticModel::affine, true, kMaxHalfWindow>,
                        S>(o);
    }
    return make_model<dualprobe::SvfEstimator<S, 1, StaticModel::unit, true, kMaxHalfWindow>, S>(
        o);
  }
  if (o.order == 1) {
    if (affine) return make_model<dualprobe::SvfEstimator<S, 1, StaticModel::affine>, S>(o);
    return make_model<dualprobe::SvfEstimator<S, 1, StaticModel::unit>, S>(o);
  }
  if (affine) return make_model<dualprobe::SvfEstimator<S, 2, StaticModel::affine>, S>(o);
  return make_model<dualprobe::SvfEstimator<S, 2, StaticModel::unit>, S>(o);
}

// A schedule for n samples as arrays of S (no copy when dtype and layout already match).
template <typename S>
struct Schedule {
  int basis = 0;
  Array<S> weights;
  Array<S> phi;
  bool has_phi = false;
};

// schedule: None, (n,) or (n, K) with 1 <= K <= 8; phi: None or (n,). Checks the shapes, and
// (K = 1) psi > 0 and (order 2) phi > 0 where finite: non-finite values are refused sample by
// sample like non-finite temperatures.
template <typename S>
Schedule<S> parse_schedule(const py::object& schedule, const py::object& phi, std::size_t n,
                           int order) {
  Schedule<S> out;
  if (schedule.is_none()) {
    if (!phi.is_none()) throw py::value_error("phi is given without a schedule");
    return out;
  }
  out.weights = Array<S>::ensure(schedule);
  if (!out.weights) {
    PyErr_Clear();
    throw py::value_error("schedule must be a numeric array");
  }
  const auto& w = out.weights;
  if (w.ndim() == 1 && std::size_t(w.shape(0)) == n) {
    out.basis = 1;
  } else if (w.ndim() == 2 && std::size_t(w.shape(0)) == n && w.shape(1) >= 1 &&
             w.shape(1) <= kMaxBasis) {
    out.basis = int(w.shape(1));
  } else {
    throw py::value_error("schedule: need shape (N,) or (N, K) with 1 <= K <= " +
                          std::to_string(kMaxBasis) + " and N the number of samples (" +
                          std::to_string(n) + ")");
  }
  if (!phi.is_none()) {
    out.phi = Array<S>::ensure(phi);
    if (!out.phi) {
      PyErr_Clear();
      throw py::value_error("phi must be a numeric array");
    }
    if (out.phi.ndim() != 1 || std::size_t(out.phi.shape(0)) != n) {
      throw py::value_error("phi: need shape (N,), N the number of samples");
    }
    out.has_phi = true;
  } else if (order == 2 && out.basis > 1) {
    throw py::value_error("order 2 with a schedule of K > 1 weights needs phi (the caller's 1/psi)");
  }
  const S* pw = out.weights.data();
  const S* pp = out.has_phi ? out.phi.data() : nullptr;
  const int k_basis = out.basis;
  std::size_t bad_psi = n;
  std::size_t bad_phi = n;
  {
    py::gil_scoped_release release;
    for (std::size_t k = 0; k < n && k_basis == 1; ++k) {
      if (std::isfinite(pw[k]) && !(pw[k] > S(0))) {
        bad_psi = k;
        break;
      }
    }
    for (std::size_t k = 0; k < n && pp != nullptr && order == 2; ++k) {
      if (std::isfinite(pp[k]) && !(pp[k] > S(0))) {
        bad_phi = k;
        break;
      }
    }
  }
  if (bad_psi < n) {
    throw py::value_error("schedule: psi must be > 0, got " + std::to_string(double(pw[bad_psi])) +
                          " at sample " + std::to_string(bad_psi));
  }
  if (bad_phi < n) {
    throw py::value_error("phi must be > 0, got " + std::to_string(double(pp[bad_phi])) +
                          " at sample " + std::to_string(bad_phi));
  }
  return out;
}

// The Python-facing object: one variant chosen at construction.
template <typename S>
struct PySvf {
  std::unique_ptr<Handle<S>> handle;
};

Options options(double ts, double tf, int order, const std::string& static_model,
                bool hysteresis, double sigma1, double sigma2, double forgetting,
                const py::object& direction_half_window, double dead_zone, int basis,
                bool windows_required = true) {
  return Options{ts,
                 tf,
                 order,
                 static_model,
                 hysteresis,
                 sigma1,
                 sigma2,
                 forgetting,
                 parse_windows(direction_half_window, hysteresis, windows_required),
                 dead_zone,
                 basis};
}

py::array_t<double> vector_array(const std::vector<double>& v) {
  py::array_t<double> out(static_cast<py::ssize_t>(v.size()));
  double* dst = out.mutable_data();
  for (std::size_t i = 0; i < v.size(); ++i) dst[i] = v[i];
  return out;
}

// A moment vector from Python, checked against the variant's length.
template <typename S>
py::array_t<double, py::array::c_style | py::array::forcecast> moment_array(
    const Handle<S>& h, const py::object& moments) {
  auto m = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(moments);
  if (!m) {
    PyErr_Clear();
    throw py::value_error("moments must be a numeric array");
  }
  if (m.ndim() != 1 || std::size_t(m.shape(0)) != h.moment_size()) {
    throw py::value_error("moments: need a vector of " + std::to_string(h.moment_size()) +
                          " entries for this variant (see moment_layout)");
  }
  return m;
}

template <typename S>
std::pair<double, double> parse_offsets(const Handle<S>& h, const py::object& offsets) {
  if (offsets.is_none()) return h.offsets();
  return offsets.cast<std::pair<double, double>>();
}

// Everything known about the accumulated moments, added to a result dict.
template <typename S>
void add_moments(py::dict& out, const Handle<S>& h) {
  out["moments"] = vector_array(h.moments(true));
  out["moment_layout"] = h.moment_layout();
  out["omega_moments"] = h.omega_moments();
  out["scatter"] = h.scatter();
  out["accumulated_noise_covariance"] = h.accumulated_noise_covariance();
  const auto o = h.offsets();
  out["offsets"] = py::make_tuple(o.first, o.second);
}

template <typename S>
void bind_class(py::module_& m, const char* name, const char* scalar) {
  using Py = PySvf<S>;
  const std::string doc =
      std::string("Streaming SVF cross-relation estimator (") + scalar +
      "; design.md 1.4, 1.5): order 1 or 2, static model 'unit' or 'affine', optional "
      "heating/cooling split (order 1), optional flow schedule of `basis` weights per sample.";
  py::class_<Py>(m, name, doc.c_str())
      .def(py::init([](double ts, double tf, int order, const std::string& static_model,
                       bool hysteresis, double sigma1, double sigma2, double forgetting,
                       const py::object& direction_half_window, double dead_zone, int basis) {
             return Py{make_handle<S>(options(ts, tf, order, static_model, hysteresis, sigma1,
                                              sigma2, forgetting, direction_half_window,
                                              dead_zone, basis))};
           }),
           "ts"_a, "tf"_a, "order"_a = 1, "static"_a = "unit", "hysteresis"_a = false,
           "sigma1"_a = 0.0, "sigma2"_a = 0.0, "forgetting"_a = 1.0,
           "direction_half_window"_a = py::none(), "dead_zone"_a = 2.0, "basis"_a = 0)
      .def(
          "update",
          [](Py& self, S t1, S t2, const py::object& schedule, const py::object& phi) {
            const int k_basis = self.handle->basis();
            if (k_basis == 0 && !(schedule.is_none() && phi.is_none())) {
              throw py::value_error("this estimator has no schedule (basis=0)");
            }
            if (k_basis > 0 && schedule.is_none()) {
              throw py::value_error("this estimator needs the sample's schedule weights");
            }
            std::vector<S> w;
            if (k_basis > 0) {
              if (k_basis == 1 && (py::isinstance<py::float_>(schedule) ||
                                   py::isinstance<py::int_>(schedule))) {
                w.push_back(schedule.cast<S>());
              } else {
                w = schedule.cast<std::vector<S>>();
              }
              if (int(w.size()) != k_basis) {
                throw py::value_error("schedule: need " + std::to_string(k_basis) + " weights");
              }
            }
            if (phi.is_none() && self.handle->order() == 2 && k_basis > 1) {
              throw py::value_error("order 2 with K > 1 schedule weights needs phi");
            }
            const S phi_value = phi.is_none() ? S(1) : phi.cast<S>();
            const auto status = self.handle->update(t1, t2, w.empty() ? nullptr : w.data(),
                                                    phi.is_none() ? nullptr : &phi_value);
            return std::string(dualprobe::to_string(status));
          },
          "t1"_a, "t2"_a, "schedule"_a = py::none(), "phi"_a = py::none(),
          "One sample; schedule: psi (basis 1) or the basis weights; phi (order 2): 1/psi by "
          "default. Returns the status ('ok', 'non_finite_input', 'invalid_argument').")
      .def(
          "update_batch",
          [](Py& self, const Array<S>& t1, const Array<S>& t2, const py::object& schedule,
             const py::object& phi) {
            const std::size_t n = checked_length<S>(t1, t2);
            const int k_basis = self.handle->basis();
            const auto sched = parse_schedule<S>(schedule, phi, n, self.handle->order());
            if (sched.basis != k_basis) {
              throw py::value_error("schedule: this estimator takes " + std::to_string(k_basis) +
                                    " weights per sample (basis), got " +
                                    std::to_string(sched.basis));
            }
            const Batch<S> batch{t1.data(), t2.data(),
                                 k_basis > 0 ? sched.weights.data() : nullptr,
                                 sched.has_phi ? sched.phi.data() : nullptr};
            std::size_t refused = 0;
            {
              py::gil_scoped_release release;
              refused = self.handle->feed(batch, 0, n);
            }
            return refused;
          },
          "t1"_a, "t2"_a, "schedule"_a = py::none(), "phi"_a = py::none(),
          "Feed arrays (schedule (N,) or (N, K), phi (N,)); returns the number of refused "
          "(non-finite) samples. ValueError for psi <= 0 or phi <= 0.")
      .def("solve", [](const Py& self) { return self.handle->solve(); })
      .def(
          "solve_moments",
          [](const Py& self, const py::object& moments, const py::object& offsets) {
            const auto vector = moment_array<S>(*self.handle, moments);
            const auto o = parse_offsets<S>(*self.handle, offsets);
            return self.handle->solve_moments(vector.data(), o.first, o.second);
          },
          "moments"_a, "offsets"_a = py::none(),
          "Solve from a moment vector (e.g. totals minus one block) with this configuration; "
          "offsets: (T1(0), T2(0)), by default this estimator's first samples.")
      .def(
          "moments", [](const Py& self) { return vector_array(self.handle->moments(true)); },
          "What solve() reads (hysteresis: the clipped tail rows included).")
      .def(
          "accumulated_moments",
          [](const Py& self) { return vector_array(self.handle->moments(false)); },
          "The rows accumulated so far (hysteresis: lagging by the look-ahead delay); "
          "consecutive snapshots differ by the rows in between.")
      .def("reset", [](Py& self) { self.handle->reset(); })
      .def_property_readonly("rows", [](const Py& self) { return self.handle->rows(); })
      .def_property_readonly("samples", [](const Py& self) { return self.handle->samples(); })
      .def_property_readonly("basis", [](const Py& self) { return self.handle->basis(); })
      .def_property_readonly(
          "offsets",
          [](const Py& self) {
            const auto o = self.handle->offsets();
            return py::make_tuple(o.first, o.second);
          },
          "The first samples (T1(0), T2(0)).")
      .def_property_readonly(
          "scatter", [](const Py& self) { return self.handle->scatter(); },
          "Projected scatter handed to GTLS.")
      .def_property_readonly(
          "noise_covariance", [](const Py& self) { return self.handle->noise_covariance(); },
          "Noise covariance of one unsplit, unscheduled row for the configured sigma1, sigma2.")
      .def_property_readonly(
          "accumulated_noise_covariance",
          [](const Py& self) { return self.handle->accumulated_noise_covariance(); },
          "Accumulated noise covariance handed to GTLS (documented columns).")
      .def_property_readonly(
          "omega_moments", [](const Py& self) { return self.handle->omega_moments(); },
          "Moments of omega = [1, (h1, h2), (phi), b_1..b_K, (p1, p2)] (no schedule: [has "
          "interval, h1, h2, p1, p2] or [1]; p_i: h_i on the row before).")
      .def_property_readonly(
          "moment_layout", [](const Py& self) { return self.handle->moment_layout(); },
          "Named slices of the moment vector.")
      .def_property_readonly(
          "nbytes", [](const Py& self) { return self.handle->nbytes(); },
          "sizeof of the C++ estimator (binding variant: 1024-sample direction window).")
      .def_property_readonly_static("max_half_window",
                                    [](const py::object&) { return kMaxHalfWindow; })
      .def_property_readonly_static("max_basis", [](const py::object&) { return kMaxBasis; });
}

template <typename S>
py::dict estimate(const Array<S>& t1, const Array<S>& t2, double ts, double tf, int order,
                  const std::string& static_model, bool hysteresis, double sigma1, double sigma2,
                  double forgetting, const py::object& direction_half_window, double dead_zone,
                  const py::object& schedule, const py::object& phi, long long block_length) {
  const std::size_t n = checked_length<S>(t1, t2);
  if (block_length < 0) throw py::value_error("block_length must be >= 0");
  const auto sched = parse_schedule<S>(schedule, phi, n, order);
  auto handle = make_handle<S>(options(ts, tf, order, static_model, hysteresis, sigma1, sigma2,
                                       forgetting, direction_half_window, dead_zone,
                                       sched.basis));
  const Batch<S> batch{t1.data(), t2.data(), sched.basis > 0 ? sched.weights.data() : nullptr,
                       sched.has_phi ? sched.phi.data() : nullptr};
  const std::size_t length = block_length > 0 ? std::size_t(block_length) : n;
  const std::size_t blocks = n == 0 ? 0 : (n + length - 1) / length;
  const std::size_t size = handle->moment_size();
  std::vector<double> block_moments;
  std::size_t refused = 0;
  {
    py::gil_scoped_release release;
    if (block_length > 0) {
      block_moments.assign(blocks * size, 0.0);
      std::vector<double> previous(size, 0.0);
      for (std::size_t b = 0; b < blocks; ++b) {
        const std::size_t begin = b * length;
        const std::size_t end = begin + length < n ? begin + length : n;
        refused += handle->feed(batch, begin, end);
        // interior boundaries: the rows so far; the end: everything solve() reads
        const std::vector<double> now = handle->moments(b + 1 == blocks);
        for (std::size_t i = 0; i < size; ++i) block_moments[b * size + i] = now[i] - previous[i];
        previous = now;
      }
    } else {
      refused = handle->feed(batch, 0, n);
    }
  }
  py::dict out = handle->solve();
  out["refused"] = refused;
  out["precision"] = sizeof(S) == sizeof(float) ? "float32" : "float64";
  add_moments(out, *handle);
  if (block_length > 0) {
    py::array_t<double> array({static_cast<py::ssize_t>(blocks), static_cast<py::ssize_t>(size)});
    double* dst = array.mutable_data();
    for (std::size_t i = 0; i < block_moments.size(); ++i) dst[i] = block_moments[i];
    out["block_moments"] = array;
    out["block_length"] = block_length;
  }
  return out;
}

#define DUALPROBE_SVF_ESTIMATE_ARGS(T1, T2)                                                      \
  T1, T2, "ts"_a, "tf"_a, "order"_a = 1, "static"_a = "unit", "hysteresis"_a = false,           \
      "sigma1"_a = 0.0, "sigma2"_a = 0.0, "forgetting"_a = 1.0,                                 \
      "direction_half_window"_a = py::none(), "dead_zone"_a = 2.0, "schedule"_a = py::none(), \
      "phi"_a = py::none(), "block_length"_a = 0

template <typename S>
void bind_estimate(py::module_& m, bool convert) {
  const char* doc =
      "Batch SVF estimate on the C++ core (float64 or float32 arrays run in their own "
      "precision); returns a dict with status, theta, polynomials, time_constants (per sensor, "
      "largest first), time_constants_heat/_cool (hysteresis), gain_ratio, offset (affine), "
      "eigenvalues, eigenvalue_ratio, rows, basis, refused, precision, moments, moment_layout, "
      "omega_moments, offsets and, with block_length > 0, block_moments (B, L): the moment "
      "vectors of consecutive blocks of block_length samples (design.md 1.5). schedule: None, "
      "psi (N,) or K <= 8 basis weights (N, K); phi (N,): order 2 (default 1/psi for K = 1).";
  if (convert) {
    m.def("estimate_svf", &estimate<S>, DUALPROBE_SVF_ESTIMATE_ARGS("t1"_a, "t2"_a), doc);
  } else {
    m.def("estimate_svf", &estimate<S>,
          DUALPROBE_SVF_ESTIMATE_ARGS("t1"_a.noconvert(), "t2"_a.noconvert()), doc);
  }
}

py::dict solve_svf_moments(const py::object& moments, double ts, double tf, int order,
                           const std::string& static_model, bool hysteresis, double sigma1,
                           double sigma2, int basis, const std::pair<double, double>& offsets,
                           const std::string& precision) {
  const Options o = options(ts, tf, order, static_model, hysteresis, sigma1, sigma2, 1.0,
                            py::none(), 2.0, basis, false);
  if (precision == "float64") {
    auto h = make_handle<double>(o);
    const auto m = moment_array<double>(*h, moments);
    return h->solve_moments(m.data(), offsets.first, offsets.second);
  }
  if (precision == "float32") {
    auto h = make_handle<float>(o);
    const auto m = moment_array<float>(*h, moments);
    return h->solve_moments(m.data(), offsets.first, offsets.second);
  }
  throw py::value_error("precision must be 'float64' or 'float32', got '" + precision + "'");
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
  m.def("solve_svf_moments", &solve_svf_moments, "moments"_a, "ts"_a, "tf"_a, "order"_a = 1,
        "static"_a = "unit", "hysteresis"_a = false, "sigma1"_a = 0.0, "sigma2"_a = 0.0,
        "basis"_a = 0, "offsets"_a = std::pair<double, double>(0.0, 0.0),
        "precision"_a = "float64",
        "Solve the SVF relation from a moment vector (estimate_svf(...)['moments'] or sums of "
        "'block_moments'); offsets = (T1(0), T2(0)) of the record ('offsets' of the batch "
        "call). Returns the dict of SvfEstimator.solve().");
}

}  // namespace dualprobe_bindings
