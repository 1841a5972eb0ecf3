// Binding of the switched time-varying first-order recursion (cpp/include/dualprobe/varying.hpp):
// the loop of a sensor whose time constant changes from one sample interval to the next.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstddef>

#include "bindings.hpp"
#include "dualprobe/varying.hpp"

namespace py = pybind11;
using namespace pybind11::literals;

namespace {

using dualprobe_bindings::Array;

Array<double> simulate_switched(const Array<double>& drive, const Array<double>& a_heat,
                                const Array<double>& f_heat, const Array<double>& a_cool,
                                const Array<double>& f_cool, double initial) {
  for (const Array<double>* x : {&drive, &a_heat, &f_heat, &a_cool, &f_cool}) {
    if (x->ndim() != 1) throw py::value_error("coefficients must be one-dimensional");
    if (x->shape(0) != drive.shape(0)) {
      throw py::value_error("drive and coefficients differ in length");
    }
  }
  const std::size_t n = static_cast<std::size_t>(drive.shape(0)) + 1;
  Array<double> out(static_cast<py::ssize_t>(n));
  double* dst = out.mutable_data();
  dualprobe::Status status;
  {
    py::gil_scoped_release release;
    status = dualprobe::simulate_switched_first_order<double>(
        drive.data(), a_heat.data(), f_heat.data(), a_cool.data(), f_cool.data(), n, initial,
        dst);
  }
  if (status != dualprobe::Status::ok) throw py::value_error("initial value must be finite");
  return out;
}

}  // namespace

namespace dualprobe_bindings {

void bind_varying(py::module_& m) {
  m.def("simulate_switched_first_order", &simulate_switched, "drive"_a, "a_heat"_a, "f_heat"_a,
        "a_cool"_a, "f_cool"_a, "initial"_a,
        "First-order recursion with coefficients per sample interval, switched by the direction "
        "of heat flow: out[0] = initial, out[k+1] = a_heat[k] out[k] + f_heat[k] if drive[k] > "
        "out[k], else a_cool[k] out[k] + f_cool[k]. Returns len(drive) + 1 values.");
}

}  // namespace dualprobe_bindings
