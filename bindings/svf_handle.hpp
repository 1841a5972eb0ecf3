// The SVF estimator behind one Python class: every C++ variant (order, static model,
// hysteresis, flow-schedule basis) is a fixed-size type; Handle<S> is the run-time interface
// the Python classes SvfEstimator / SvfEstimatorF hold, Model<E, S> implements it for one
// variant E (the batch loop inside, so the per-sample update is not a virtual call). The
// unscheduled variants are built in svf.cpp, the scheduled ones in svf_schedule1.cpp (order 1)
// and svf_schedule2.cpp (order 2), so the three compile in parallel.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "bindings.hpp"
#include "dualprobe/svf_estimator.hpp"

namespace dualprobe_bindings {
namespace svf {

// The host has memory to spare: the bindings accept look-ahead windows up to 1024 samples
// (the Python layer may choose up to tf/Ts, e.g. ~550 at 100 Hz); the ECU default is 128.
constexpr int kMaxHalfWindow = 1024;
constexpr int kMaxBasis = 8;

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
  int basis;  // 0: no schedule; K: K weights per sample
};

// One batch of samples: weights n x basis (row-major) or null; phi n values or null (order 2
// with K = 1: 1/psi).
template <typename S>
struct Batch {
  const S* t1;
  const S* t2;
  const S* weights;
  const S* phi;
};

template <typename S>
class Handle {
 public:
  virtual ~Handle() = default;
  virtual int basis() const noexcept = 0;
  virtual int order() const noexcept = 0;
  virtual bool hysteresis() const noexcept = 0;
  // One sample (weights: basis() values or null; phi: null -> 1/psi or unused).
  virtual dualprobe::Status update(S t1, S t2, const S* weights, const S* phi) noexcept = 0;
  // Samples [begin, end) of a batch; returns the number refused.
  virtual std::size_t feed(const Batch<S>& batch, std::size_t begin,
                           std::size_t end) noexcept = 0;
  virtual void reset() noexcept = 0;
  // finished: what solve() reads (the hysteresis tail included); else the rows so far.
  virtual std::vector<double> moments(bool finished) const = 0;
  virtual std::size_t moment_size() const noexcept = 0;
  // Called with the GIL held; they release it around the solve.
  virtual pybind11::dict solve() const = 0;
  virtual pybind11::dict solve_moments(const double* moments, double offset1,
                                       double offset2) const = 0;
  virtual pybind11::dict moment_layout() const = 0;
  virtual pybind11::array_t<double> omega_moments() const = 0;
  virtual pybind11::array_t<double> scatter() const = 0;
  virtual pybind11::array_t<double> noise_covariance() const = 0;
  virtual pybind11::array_t<double> accumulated_noise_covariance() const = 0;
  virtual double rows() const noexcept = 0;
  virtual std::uint64_t samples() const noexcept = 0;
  virtual std::size_t nbytes() const noexcept = 0;
  virtual std::pair<double, double> offsets() const noexcept = 0;
};

template <typename V>
pybind11::list to_list(const V& v) {
  pybind11::list out;
  for (Eigen::Index i = 0; i < v.size(); ++i) out.append(double(v[i]));
  return out;
}

template <typename M>
pybind11::array_t<double> to_array(const M& m) {
  pybind11::array_t<double> out({static_cast<pybind11::ssize_t>(m.rows()),
                                 static_cast<pybind11::ssize_t>(m.cols())});
  auto view = out.template mutable_unchecked<2>();
  for (Eigen::Index i = 0; i < m.rows(); ++i)
    for (Eigen::Index j = 0; j < m.cols(); ++j) view(i, j) = double(m(i, j));
  return out;
}

template <typename E>
pybind11::dict result_dict(const E& estimator, const typename E::Result& r) {
  using namespace pybind11::literals;
  namespace py = pybind11;
  py::dict out("status"_a = dualprobe::to_string(r.status), "order"_a = E::order,
               "static"_a = E::affine ? "affine" : "unit", "hysteresis"_a = E::hysteresis,
               "basis"_a = E::schedule_basis,
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

template <typename E, typename S>
class Model final : public Handle<S> {
 public:
  using Layout = typename E::MomentLayout;
  static constexpr int kBasis = E::schedule_basis;

  E estimator;

  int basis() const noexcept override { return kBasis; }
  int order() const noexcept override { return E::order; }
  bool hysteresis() const noexcept override { return E::hysteresis; }

  dualprobe::Status update(S t1, S t2, const S* weights, const S* phi) noexcept override {
    return step(t1, t2, weights, phi);
  }

  std::size_t feed(const Batch<S>& b, std::size_t begin, std::size_t end) noexcept override {
    std::size_t refused = 0;
    for (std::size_t k = begin; k < end; ++k) {
      const S* w = b.weights == nullptr ? nullptr : b.weights + k * std::size_t(kBasis);
      const S* phi = b.phi == nullptr ? nullptr : b.phi + k;
      if (step(b.t1[k], b.t2[k], w, phi) != dualprobe::Status::ok) ++refused;
    }
    return refused;
  }

  void reset() noexcept override { estimator.reset(); }

  std::vector<double> moments(bool finished) const override {
    const auto m = finished ? estimator.moments() : estimator.accumulated_moments();
    return std::vector<double>(m.data(), m.data() + m.size());
  }
  std::size_t moment_size() const noexcept override { return std::size_t(Layout::size); }

  pybind11::dict solve() const override {
    typename E::Result r;
    {
      pybind11::gil_scoped_release release;
      r = estimator.solve();
    }
    return result_dict(estimator, r);
  }

  pybind11::dict solve_moments(const double* moments, double offset1,
                               double offset2) const override {
    typename E::MomentVector m;
    for (int i = 0; i < Layout::size; ++i) m[i] = moments[i];
    typename E::Result r;
    {
      pybind11::gil_scoped_release release;
      r = estimator.solve(m, S(offset1), S(offset2));
    }
    pybind11::dict out = result_dict(estimator, r);
    out["scatter"] = to_array(estimator.scatter(m, S(offset1), S(offset2)));
    out["accumulated_noise_covariance"] = to_array(estimator.accumulated_noise_covariance(m));
    return out;
  }

  pybind11::dict moment_layout() const override {
    namespace py = pybind11;
    auto slice = [](int start, int length) { return py::slice(start, start + length, 1); };
    py::dict out;
    out["scatter"] = slice(Layout::scatter, Layout::scatter_size);
    out["cross"] = slice(Layout::cross, Layout::cross_size);
    out["extra_cross"] = slice(Layout::extra_cross, Layout::extra_cross_size);
    out["gram"] = slice(Layout::gram, Layout::gram_size);
    out["omega"] = slice(Layout::omega, Layout::omega_size);
    out["rows"] = slice(Layout::rows, 1);
    return out;
  }

  pybind11::array_t<double> omega_moments() const override {
    return to_array(estimator.omega_moments());
  }
  pybind11::array_t<double> scatter() const override { return to_array(estimator.scatter()); }
  pybind11::array_t<double> noise_covariance() const override {
    return to_array(estimator.noise_covariance());
  }
  pybind11::array_t<double> accumulated_noise_covariance() const override {
    return to_array(estimator.accumulated_noise_covariance());
  }
  double rows() const noexcept override { return double(estimator.rows()); }
  std::uint64_t samples() const noexcept override { return estimator.samples(); }
  std::size_t nbytes() const noexcept override { return sizeof(E); }
  std::pair<double, double> offsets() const noexcept override {
    return {double(estimator.offset1()), double(estimator.offset2())};
  }

 private:
  dualprobe::Status step(S t1, S t2, const S* weights, const S* phi) noexcept {
    if constexpr (kBasis == 0) {
      (void)weights, (void)phi;
      return estimator.update(t1, t2);
    } else if constexpr (kBasis == 1) {
      if (phi == nullptr) return estimator.update(t1, t2, weights[0]);
      return estimator.update(t1, t2, weights, *phi);
    } else {
      return estimator.update(t1, t2, weights, phi == nullptr ? S(1) : *phi);
    }
  }
};

// Configures the estimator of a new model; ValueError on an invalid configuration.
template <typename E, typename S>
std::unique_ptr<Handle<S>> make_model(const Options& o) {
  auto model = std::make_unique<Model<E, S>>();
  dualprobe::SvfConfig<S> config;
  config.sample_interval = S(o.ts);
  config.filter_time_constant = S(o.tf);
  config.sigma1 = S(o.sigma1);
  config.sigma2 = S(o.sigma2);
  config.forgetting = S(o.forgetting);
  config.direction_half_window1 = o.windows.first;
  config.direction_half_window2 = o.windows.second;
  config.dead_zone = S(o.dead_zone);
  if (model->estimator.configure(config) != dualprobe::Status::ok) {
    throw pybind11::value_error(
        "invalid SVF configuration: need ts > 0, tf > 0 with 1e-7 <= ts/tf <= 100, sigma1, "
        "sigma2 >= 0, 0 < forgetting <= 1 and, with hysteresis, 1 <= direction_half_window <= " +
        std::to_string(kMaxHalfWindow) + " and dead_zone >= 0");
  }
  return model;
}

// Scheduled variants (basis >= 1), defined in svf_schedule1.cpp / svf_schedule2.cpp.
template <typename S>
std::unique_ptr<Handle<S>> make_scheduled_order1(const Options& o);
template <typename S>
std::unique_ptr<Handle<S>> make_scheduled_order2(const Options& o);

}  // namespace svf
}  // namespace dualprobe_bindings
