// Bindings of the causal Kalman reconstruction (cpp/include/dualprobe/kalman.hpp).
// KalmanReconstructor (double) and KalmanReconstructorF (float) are the largest model the core
// supports (6 states, 16 hysteresis modes, a GLR window of up to 256): one Python class serves
// every sensor order. NumPy arrays are read in place (matching dtype), batch loops run without
// the GIL, results come back as NumPy arrays.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "bindings.hpp"
#include "dualprobe/kalman.hpp"

namespace py = pybind11;
using namespace pybind11::literals;

namespace {

using dualprobe_bindings::Array;
using dualprobe_bindings::checked_length;

constexpr int kBindingMaxWindow = 256;  // the host has memory to spare; the ECU default is 64

template <typename S>
using Reconstructor = dualprobe::KalmanReconstructor<S, 6, 16, kBindingMaxWindow>;

std::vector<double> as_taus(const char* name, const py::object& value, bool allow_none) {
  if (value.is_none()) {
    if (allow_none) return {};
    throw py::value_error(std::string(name) + " is required");
  }
  std::vector<double> taus;
  if (py::isinstance<py::float_>(value) || py::isinstance<py::int_>(value)) {
    taus.push_back(value.cast<double>());
  } else {
    taus = value.cast<std::vector<double>>();
  }
  if (taus.size() != 1 && taus.size() != 2) {
    throw py::value_error(std::string(name) + ": need 1 or 2 time constants, got " +
                          std::to_string(taus.size()));
  }
  for (double t : taus) {
    if (!(t > 0.0) || !std::isfinite(t)) {
      throw py::value_error(std::string(name) + ": time constants must be finite and > 0");
    }
  }
  return taus;
}

std::pair<double, double> as_sigma(const py::object& value) {
  if (py::isinstance<py::float_>(value) || py::isinstance<py::int_>(value)) {
    const double s = value.cast<double>();
    return {s, s};
  }
  const auto v = value.cast<std::vector<double>>();
  if (v.size() != 2) throw py::value_error("sigma: one value or one per sensor");
  return {v[0], v[1]};
}

dualprobe::GasModel parse_gas(const std::string& gas) {
  if (gas == "rw") return dualprobe::GasModel::random_walk;
  if (gas == "irw") return dualprobe::GasModel::integrated_random_walk;
  throw py::value_error("gas must be 'rw' or 'irw', got '" + gas + "'");
}

template <typename S>
dualprobe::KalmanConfig<S> make_config(double ts, const py::object& taus1,
                                       const py::object& taus2, const py::object& sigma, double q,
                                       const std::string& gas, const py::object& taus1_cool,
                                       const py::object& taus2_cool, bool detect_jumps,
                                       int window, double false_alarm) {
  dualprobe::KalmanConfig<S> c;
  c.sample_interval = S(ts);
  c.gas = parse_gas(gas);
  const auto heat1 = as_taus("taus1", taus1, false);
  const auto heat2 = as_taus("taus2", taus2, false);
  const auto cool1 = as_taus("taus1_cool", taus1_cool, true);
  const auto cool2 = as_taus("taus2_cool", taus2_cool, true);
  if (!cool1.empty() && cool1.size() != heat1.size()) {
    throw py::value_error("taus1_cool: need as many time constants as taus1");
  }
  if (!cool2.empty() && cool2.size() != heat2.size()) {
    throw py::value_error("taus2_cool: need as many time constants as taus2");
  }
  c.order1 = int(heat1.size());
  c.order2 = int(heat2.size());
  for (std::size_t i = 0; i < heat1.size(); ++i) {
    c.taus1[i] = S(heat1[i]);
    c.taus1_cool[i] = cool1.empty() ? S(0) : S(cool1[i]);
  }
  for (std::size_t i = 0; i < heat2.size(); ++i) {
    c.taus2[i] = S(heat2[i]);
    c.taus2_cool[i] = cool2.empty() ? S(0) : S(cool2[i]);
  }
  const auto s = as_sigma(sigma);
  c.sigma1 = S(s.first);
  c.sigma2 = S(s.second);
  c.intensity = S(q);
  c.detect_jumps = detect_jumps;
  c.window = window;
  c.false_alarm = S(false_alarm);
  return c;
}

template <typename S>
std::unique_ptr<Reconstructor<S>> make_reconstructor(const dualprobe::KalmanConfig<S>& c) {
  auto r = std::make_unique<Reconstructor<S>>();
  if (r->configure(c) != dualprobe::Status::ok) {
    throw py::value_error(
        "invalid Kalman configuration: need ts > 0, time constants > 0 (cooling ones >= 0), "
        "sigma > 0, q >= 0, 1 <= window <= 256, 0 < false_alarm < 1, and a model that is "
        "finite in the chosen precision");
  }
  return r;
}

// Any array-like (lists included) as an array, its dtype kept.
py::array as_array(const py::object& value) {
  auto out = py::array::ensure(value);
  if (!out) {
    PyErr_Clear();
    throw py::value_error("signals must be array-like");
  }
  return out;
}

// A C-contiguous array of S (a copy only when the input is strided or of another dtype).
template <typename S>
Array<S> numeric(const py::array& a) {
  auto out = Array<S>::ensure(a);
  if (!out) {
    PyErr_Clear();
    throw py::value_error("signals must be numeric arrays");
  }
  return out;
}

template <typename S>
py::array_t<double> matrix_out(const Eigen::Matrix<S, 6, 6>& m, int n) {
  py::array_t<double> out({n, n});
  auto view = out.mutable_unchecked<2>();
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) view(i, j) = double(m(i, j));
  return out;
}

template <typename S>
py::object jump_dict(const Reconstructor<S>& r) {
  if (r.jump_count() == 0) return py::none();
  const auto& j = r.last_jump();
  return py::dict("detected_at"_a = j.detected_at, "interval"_a = j.interval,
                  "size"_a = double(j.size), "fraction"_a = double(j.fraction));
}

#define DUALPROBE_KALMAN_CONFIG_ARGS                                                   \
  "ts"_a, "taus1"_a, "taus2"_a, "sigma"_a, "q"_a, py::kw_only(), "gas"_a = "rw",       \
      "taus1_cool"_a = py::none(), "taus2_cool"_a = py::none(), "detect_jumps"_a = true, \
      "window"_a = 64, "false_alarm"_a = 1e-6

template <typename S>
void bind_class(py::module_& m, const char* name) {
  using R = Reconstructor<S>;
  py::class_<R>(m, name,
                "Causal gas-temperature reconstruction (Kalman filter with GLR jump detection, "
                "dualprobe.reference.kalman). taus: 1 or 2 per sensor; sigma: one value or "
                "one per sensor; q: gas intensity (K^2/s rw, K^2/s^3 irw).")
      .def(py::init([](double ts, const py::object& taus1, const py::object& taus2,
                       const py::object& sigma, double q, const std::string& gas,
                       const py::object& taus1_cool, const py::object& taus2_cool,
                       bool detect_jumps, int window, double false_alarm) {
             return make_reconstructor<S>(make_config<S>(ts, taus1, taus2, sigma, q, gas,
                                                         taus1_cool, taus2_cool, detect_jumps,
                                                         window, false_alarm));
           }),
           DUALPROBE_KALMAN_CONFIG_ARGS)
      .def(
          "update",
          [](R& r, S t1, S t2) { return std::string(dualprobe::to_string(r.update(t1, t2))); },
          "t1"_a, "t2"_a, "One sample pair; returns the status ('ok', 'non_finite_input', ...).")
      .def(
          "skip", [](R& r) { return std::string(dualprobe::to_string(r.skip())); },
          "A sample instant without measurement (prediction only).")
      .def(
          "update_batch",
          [](R& r, const Array<S>& t1, const Array<S>& t2) {
            const std::size_t n = checked_length<S>(t1, t2);
            Array<S> out(static_cast<py::ssize_t>(n));
            S* dst = out.mutable_data();
            const S* p1 = t1.data();
            const S* p2 = t2.data();
            {
              py::gil_scoped_release release;
              r.update_block(p1, p2, n, dst);
            }
            return out;
          },
          "t1"_a, "t2"_a,
          "Filtered gas temperature per sample pair; NaN where a pair was refused (non-finite: "
          "the instant is skipped, later samples stay on their time grid).")
      .def("reset", &R::reset)
      .def(
          "retune",
          [](R& r, double ts, const py::object& taus1, const py::object& taus2,
             const py::object& sigma, double q, const std::string& gas,
             const py::object& taus1_cool, const py::object& taus2_cool, bool detect_jumps,
             int window, double false_alarm) {
            const auto c = make_config<S>(ts, taus1, taus2, sigma, q, gas, taus1_cool,
                                          taus2_cool, detect_jumps, window, false_alarm);
            if (r.retune(c) != dualprobe::Status::ok) {
              throw py::value_error(
                  "retune: invalid configuration, or the gas model / sensor orders changed");
            }
          },
          DUALPROBE_KALMAN_CONFIG_ARGS, "New parameters, same state layout; keeps the state.")
      .def_property_readonly("gas", [](const R& r) { return double(r.gas()); })
      .def_property_readonly("gas_variance", [](const R& r) { return double(r.gas_variance()); })
      .def_property_readonly("state",
                             [](const R& r) {
                               const auto x = r.state();
                               py::array_t<double> out(r.states());
                               for (int i = 0; i < r.states(); ++i) out.mutable_at(i) = double(x[i]);
                               return out;
                             })
      .def_property_readonly("covariance",
                             [](const R& r) { return matrix_out<S>(r.covariance(), r.states()); })
      .def("transition", [](const R& r, int mode) {
             if (mode < 0 || mode >= r.modes()) throw py::index_error("mode out of range");
             return matrix_out<S>(r.transition(mode), r.states());
           }, "mode"_a = 0)
      .def("process_noise", [](const R& r, int mode) {
             if (mode < 0 || mode >= r.modes()) throw py::index_error("mode out of range");
             return matrix_out<S>(r.process_noise(mode), r.states());
           }, "mode"_a = 0)
      .def_property_readonly("states", &R::states)
      .def_property_readonly("modes", &R::modes)
      .def_property_readonly("samples", &R::samples)
      .def_property_readonly("log_likelihood",
                             [](const R& r) { return double(r.log_likelihood()); })
      .def_property_readonly("threshold", [](const R& r) { return double(r.threshold()); })
      .def_property_readonly("jump_count", &R::jump_count)
      .def_property_readonly("last_jump", &jump_dict<S>);
}

// Schedule levels are quantised in log steps of 0.5 %: the filter is retuned (rediscretised)
// only when the level moves by a step, and a time constant 0.25 % off changes the causal
// reconstruction far below the noise.
constexpr double kScheduleStep = 0.00498754151103897;  // log(1.005)

double schedule_level(double value) {
  return std::exp(std::round(std::log(value) / kScheduleStep) * kScheduleStep);
}

template <typename S>
dualprobe::KalmanConfig<S> scaled_config(dualprobe::KalmanConfig<S> c, double level) {
  for (int j = 0; j < 2; ++j) {
    c.taus1[j] = S(double(c.taus1[j]) * level);
    c.taus2[j] = S(double(c.taus2[j]) * level);
    c.taus1_cool[j] = S(double(c.taus1_cool[j]) * level);
    c.taus2_cool[j] = S(double(c.taus2_cool[j]) * level);
  }
  return c;
}

template <typename S>
py::dict kalman_filter(const Array<S>& t1, const Array<S>& t2, double ts,
                       const py::object& taus1, const py::object& taus2,
                       const py::object& sigma, double q, const std::string& gas,
                       const py::object& taus1_cool, const py::object& taus2_cool,
                       bool detect_jumps, int window, double false_alarm,
                       const py::object& schedule) {
  const std::size_t n = checked_length<S>(t1, t2);
  std::vector<double> levels;
  if (!schedule.is_none()) {
    const auto values = py::array_t<double, py::array::c_style | py::array::forcecast>(schedule);
    if (values.ndim() != 1 || static_cast<std::size_t>(values.size()) != n) {
      throw py::value_error("schedule must hold one value per sample");
    }
    levels.resize(n);
    for (std::size_t k = 0; k < n; ++k) {
      const double v = values.at(static_cast<py::ssize_t>(k));
      if (!(std::isfinite(v) && v > 0.0)) throw py::value_error("schedule must be finite and > 0");
      levels[k] = v;
    }
    // time constants that follow the flow come with a continuously moving gas: no jumps to
    // detect, and a retune would drop the GLR's candidates anyway
    detect_jumps = false;
  }
  const auto base = make_config<S>(ts, taus1, taus2, sigma, q, gas, taus1_cool, taus2_cool,
                                   detect_jumps, window, false_alarm);
  double current = levels.empty() ? 1.0 : schedule_level(levels[0]);
  auto r = make_reconstructor<S>(scaled_config(base, current));
  Array<S> gas_out(static_cast<py::ssize_t>(n));
  Array<S> variance(static_cast<py::ssize_t>(n));
  std::vector<std::int64_t> detected;
  std::vector<std::int64_t> interval;
  std::vector<double> size;
  std::size_t refused = 0;
  {
    py::gil_scoped_release release;
    const S* p1 = t1.data();
    const S* p2 = t2.data();
    S* g = gas_out.mutable_data();
    S* v = variance.mutable_data();
    for (std::size_t k = 0; k < n; ++k) {
      if (!levels.empty() && k > 0) {
        // interval k-1 -> k: the mean of its ends, as the smoother's model
        const double level = schedule_level(0.5 * (levels[k - 1] + levels[k]));
        if (level != current && r->retune(scaled_config(base, level)) == dualprobe::Status::ok) {
          current = level;
        }
      }
      refused += r->update_block(p1 + k, p2 + k, 1, g + k);
      v[k] = r->gas_variance();
      if (r->jump_detected()) {
        detected.push_back(r->last_jump().detected_at);
        interval.push_back(r->last_jump().interval);
        size.push_back(double(r->last_jump().size));
      }
    }
  }
  return py::dict("gas"_a = gas_out, "gas_variance"_a = variance,
                  "jump_detected_at"_a = py::array_t<std::int64_t>(detected.size(), detected.data()),
                  "jump_interval"_a = py::array_t<std::int64_t>(interval.size(), interval.data()),
                  "jump_size"_a = py::array_t<double>(size.size(), size.data()),
                  "log_likelihood"_a = double(r->log_likelihood()), "refused"_a = refused);
}

constexpr const char* kFilterDoc =
    "Causal Kalman reconstruction of a whole record (C++ core; in float when t1 and t2 are "
    "both float32, else in double); returns a dict with gas, gas_variance, jump_detected_at, jump_interval, "
    "jump_size, log_likelihood, refused. schedule (N,): the time constants in effect at sample k "
    "are the given ones times schedule[k] (interval k-1 -> k: the mean of its ends, quantised "
    "in 0.5 % log steps); jump detection is off with a schedule.";

}  // namespace

namespace dualprobe_bindings {

void bind_kalman(pybind11::module_& m) {
  bind_class<double>(m, "KalmanReconstructor");
  bind_class<float>(m, "KalmanReconstructorF");
  // Dispatch on dtype (not on overload matching, which would send a non-contiguous float32
  // view to the converting float64 overload): float32 pairs run in float, all else in double.
  m.def(
      "kalman_filter",
      [](const py::object& signal1, const py::object& signal2, double ts, const py::object& taus1,
         const py::object& taus2, const py::object& sigma, double q, const std::string& gas,
         const py::object& taus1_cool, const py::object& taus2_cool, bool detect_jumps,
         int window, double false_alarm, const py::object& schedule) {
        const py::array t1 = as_array(signal1);
        const py::array t2 = as_array(signal2);
        const auto f32 = py::dtype::of<float>();
        if (t1.dtype().is(f32) && t2.dtype().is(f32)) {
          return kalman_filter<float>(numeric<float>(t1), numeric<float>(t2), ts, taus1, taus2,
                                      sigma, q, gas, taus1_cool, taus2_cool, detect_jumps,
                                      window, false_alarm, schedule);
        }
        return kalman_filter<double>(numeric<double>(t1), numeric<double>(t2), ts, taus1, taus2,
                                     sigma, q, gas, taus1_cool, taus2_cool, detect_jumps, window,
                                     false_alarm, schedule);
      },
      "t1"_a, "t2"_a, DUALPROBE_KALMAN_CONFIG_ARGS, "schedule"_a = py::none(), kFilterDoc);
}

}  // namespace dualprobe_bindings
