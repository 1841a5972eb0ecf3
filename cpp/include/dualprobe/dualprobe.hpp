// Umbrella header of the C++ core.
#pragma once

#include "dualprobe/difference_estimator.hpp"
#include "dualprobe/first_order.hpp"
#include "dualprobe/gtls.hpp"
#include "dualprobe/kalman.hpp"
#include "dualprobe/reconstruct.hpp"
#include "dualprobe/scatter.hpp"
#include "dualprobe/simulation.hpp"
#include "dualprobe/status.hpp"
#include "dualprobe/svf_estimator.hpp"
#include "dualprobe/varying.hpp"
