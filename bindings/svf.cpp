// Bindings of the streaming SVF estimator (cpp/include/dualprobe/svf_estimator.hpp).
#include "bindings.hpp"

namespace dualprobe_bindings {

void bind_svf(pybind11::module_& /*m*/) {}

}  // namespace dualprobe_bindings
