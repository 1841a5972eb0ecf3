// Deterministic test signals for the C API and firmware tests: a realistic dual Pt-100 pair
// (band-limited fluctuating gas plus steps, exact first-order sensors, white noise), cheap
// enough to generate 10^8 samples in a soak test. No <random> distributions, whose output
// differs between standard libraries.
#pragma once

#include <cmath>
#include <cstdint>

namespace dualprobe_test {

// xoshiro128+ style generator (small state, fast); uniform in [0, 1).
class Rng {
 public:
  explicit Rng(std::uint64_t seed) noexcept {
    for (auto& word : state_) {
      seed += 0x9E3779B97F4A7C15ull;  // splitmix64
      std::uint64_t z = seed;
      z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
      z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
      word = z ^ (z >> 31);
    }
  }
  double uniform() noexcept {
    const std::uint64_t result = state_[0] + state_[3];
    const std::uint64_t t = state_[1] << 17;
    state_[2] ^= state_[0];
    state_[3] ^= state_[1];
    state_[1] ^= state_[2];
    state_[0] ^= state_[3];
    state_[2] ^= t;
    state_[3] = (state_[3] << 45) | (state_[3] >> 19);
    return static_cast<double>(result >> 11) * 0x1.0p-53;
  }
  // Unit-variance, zero-mean, nearly Gaussian (Irwin-Hall of four uniforms): white sensor
  // noise does not need exact Gaussian tails here.
  double normal() noexcept {
    return (uniform() + uniform() + uniform() + uniform() - 2.0) * 1.7320508075688772;
  }

 private:
  std::uint64_t state_[4]{};
};

// Gas temperature: a mean level that jumps every `hold` samples (to a new level within
// +/- step_amplitude) plus an Ornstein-Uhlenbeck fluctuation of standard deviation
// `fluctuation` and correlation time `correlation` (s). Sensors: exact ZOH first-order models.
struct PairSource {
  double ts = 0.01;
  double tau1 = 1.248;
  double tau2 = 2.895;
  double mean = 200.0;
  double step_amplitude = 50.0;
  double fluctuation = 5.0;
  double correlation = 2.0;
  double noise1 = 0.02;
  double noise2 = 0.02;
  std::uint64_t hold = 1500;

  explicit PairSource(std::uint64_t seed) : rng_(seed) {}

  void start() noexcept {
    a1_ = std::exp(-ts / tau1);
    a2_ = std::exp(-ts / tau2);
    phi_ = std::exp(-ts / correlation);
    drive_ = fluctuation * std::sqrt(1.0 - phi_ * phi_);
    level_ = mean;
    gas_ = mean;
    t1_ = mean;
    t2_ = mean;
    k_ = 0;
  }

  // Advances one sample; the noisy sensor readings are returned, the truth kept.
  void next(double* t1, double* t2) noexcept {
    if (k_ % hold == 0 && k_ > 0) level_ = mean + step_amplitude * (2.0 * rng_.uniform() - 1.0);
    ou_ = phi_ * ou_ + drive_ * rng_.normal();
    const double previous_gas = gas_;
    gas_ = level_ + ou_;
    t1_ = a1_ * t1_ + (1.0 - a1_) * previous_gas;
    t2_ = a2_ * t2_ + (1.0 - a2_) * previous_gas;
    *t1 = t1_ + noise1 * rng_.normal();
    *t2 = t2_ + noise2 * rng_.normal();
    ++k_;
  }

  double gas() const noexcept { return gas_; }

 private:
  Rng rng_;
  double a1_ = 0, a2_ = 0, phi_ = 0, drive_ = 0;
  double level_ = 0, ou_ = 0, gas_ = 0, t1_ = 0, t2_ = 0;
  std::uint64_t k_ = 0;
};

}  // namespace dualprobe_test
