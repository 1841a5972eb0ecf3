// Bindings of the causal Kalman reconstruction (cpp/include/dualprobe/kalman.hpp).
#include "bindings.hpp"

namespace dualprobe_bindings {

void bind_kalman(pybind11::module_& /*m*/) {}

}  // namespace dualprobe_bindings
