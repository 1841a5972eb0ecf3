// Registration functions of the binding files; module.cpp calls each once.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstddef>

namespace dualprobe_bindings {

void bind_svf(pybind11::module_& m);
void bind_kalman(pybind11::module_& m);
void bind_svf_filter(pybind11::module_& m);
void bind_banded(pybind11::module_& m);
void bind_intervals(pybind11::module_& m);
void bind_varying(pybind11::module_& m);

// NumPy array of S: taken without a copy when the dtype and layout already match.
template <typename S>
using Array = pybind11::array_t<S, pybind11::array::c_style | pybind11::array::forcecast>;

// Length of two 1-D signals that must pair up sample by sample (ValueError otherwise).
template <typename S>
std::size_t checked_length(const Array<S>& a, const Array<S>& b) {
  if (a.ndim() != 1 || b.ndim() != 1) {
    throw pybind11::value_error("signals must be one-dimensional");
  }
  if (a.shape(0) != b.shape(0)) throw pybind11::value_error("the two signals differ in length");
  return static_cast<std::size_t>(a.shape(0));
}

}  // namespace dualprobe_bindings
