// Registration functions of the binding files; module.cpp calls each once.
#pragma once

#include <pybind11/pybind11.h>

namespace dualprobe_bindings {

void bind_svf(pybind11::module_& m);
void bind_kalman(pybind11::module_& m);

}  // namespace dualprobe_bindings
