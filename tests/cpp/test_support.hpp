// Shared helpers of the C++ tests: deterministic noise-free data from the difference equation.
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

#include "dualprobe/first_order.hpp"

namespace dualprobe::test {

struct PairSeries {
  std::vector<double> gas;
  std::vector<double> t1;
  std::vector<double> t2;
};

// A multistep gas profile held over each sample (ZOH), levels drawn by a fixed LCG so the
// tests need no <random> distribution whose output differs between standard libraries.
inline PairSeries difference_equation_pair(std::size_t n, double tau1, double tau2, double ts,
                                           std::uint32_t seed = 7u, std::size_t hold = 40) {
  PairSeries series;
  series.gas.resize(n);
  series.t1.resize(n);
  series.t2.resize(n);
  std::uint32_t state = seed;
  double level = 300.0;
  for (std::size_t k = 0; k < n; ++k) {
    if (k % hold == 0) {
      state = state * 1664525u + 1013904223u;
      level = 300.0 + 20.0 * (static_cast<double>(state >> 8) / 16777216.0 - 0.5);
    }
    series.gas[k] = level;
  }
  FirstOrderSensor<double> s1;
  FirstOrderSensor<double> s2;
  s1.set_time_constant(tau1, ts);
  s2.set_time_constant(tau2, ts);
  series.t1[0] = 295.0;
  series.t2[0] = 290.0;
  for (std::size_t k = 1; k < n; ++k) {
    series.t1[k] = s1.step(series.t1[k - 1], series.gas[k - 1]);
    series.t2[k] = s2.step(series.t2[k - 1], series.gas[k - 1]);
  }
  return series;
}

}  // namespace dualprobe::test
