// The causal Kalman reconstruction (kalman.hpp): its discretisation against closed forms, its
// accuracy against the true gas temperature on data simulated here exactly (piecewise-affine
// gas, analytic sensor responses, off-grid steps), float against double, the contract (refused
// samples, bad configurations, capacity limits), no heap, and a long float soak.
#define EIGEN_RUNTIME_NO_MALLOC
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdint>
#include <limits>
#include <random>
#include <utility>
#include <vector>

#include "dualprobe/kalman.hpp"

namespace {

using dualprobe::GasModel;
using dualprobe::KalmanConfig;
using dualprobe::KalmanReconstructor;
using dualprobe::Status;

// ---- exact simulation ----------------------------------------------------------------------

// Gas: affine pieces level + slope (t - start), a new piece at each break (a step if the level
// jumps there).
struct Piece {
  double start;
  double level;
  double slope;
};

struct Gas {
  std::vector<Piece> pieces;
  std::vector<double> jumps;  // times of discontinuities
  double at(double t) const {
    std::size_t i = 0;
    while (i + 1 < pieces.size() && pieces[i + 1].start <= t) ++i;
    return pieces[i].level + pieces[i].slope * (t - pieces[i].start);
  }
};

// A sensor: 1 or 2 first-order stages (distinct time constants for 2); the single stage of a
// first-order sensor may be hysteretic (tau_cool while the gas is below it; exact for constant
// pieces, where the direction cannot change within a piece).
struct Sensor {
  std::vector<double> taus;
  double tau_cool = 0.0;  // 0: no hysteresis
};

// Advances the stage states over d with the gas u0 + r s (0 <= s <= d): exact.
void advance(const Sensor& sensor, std::vector<double>& z, double u0, double r, double d) {
  const double a = sensor.taus[0];
  if (sensor.taus.size() == 1) {
    const double tau = (sensor.tau_cool > 0.0 && u0 < z[0] && r == 0.0) ? sensor.tau_cool : a;
    z[0] = u0 + r * d - r * tau + (z[0] - u0 + r * tau) * std::exp(-d / tau);
    return;
  }
  const double b = sensor.taus[1];
  const double c1 = z[0] - u0 + r * a;  // z1(s) = u0 + r s - r a + c1 exp(-s/a)
  const double shifted = u0 - r * a;    // affine part of stage 2's input
  const double affine = shifted + r * d - r * b + (z[1] - shifted + r * b) * std::exp(-d / b);
  const double transient = c1 * a / (a - b) * (std::exp(-d / a) - std::exp(-d / b));
  z[0] = u0 + r * d - r * a + c1 * std::exp(-d / a);
  z[1] = affine + transient;
}

struct Record {
  double ts = 0.1;
  std::vector<double> gas;  // at the sample instants
  std::vector<double> t1;
  std::vector<double> t2;
  std::vector<bool> near_jump;  // a jump within two samples (excluded from accuracy figures)
  std::vector<double> jumps;
};

Record simulate(const Gas& gas, const Sensor& s1, const Sensor& s2, double ts, std::size_t n,
                double noise, std::uint32_t seed) {
  Record rec;
  rec.ts = ts;
  rec.jumps = gas.jumps;
  std::vector<double> z1(s1.taus.size(), gas.at(0.0));
  std::vector<double> z2(s2.taus.size(), gas.at(0.0));
  std::mt19937 engine(seed);
  auto uniform = [&engine]() { return (double(engine()) + 0.5) / 4294967296.0; };
  auto normal = [&uniform]() {  // Box-Muller: portable, unlike std::normal_distribution
    return std::sqrt(-2.0 * std::log(uniform())) * std::cos(6.283185307179586 * uniform());
  };
  double t = 0.0;
  std::size_t piece = 0;
  std::size_t next_jump = 0;  // first jump after t_k - 2 Ts
  for (std::size_t k = 0; k < n; ++k) {
    const double target = double(k) * ts;
    while (t < target) {  // integrate piece by piece up to the sample instant
      while (piece + 1 < gas.pieces.size() && gas.pieces[piece + 1].start <= t) ++piece;
      const double end = piece + 1 < gas.pieces.size() && gas.pieces[piece + 1].start < target
                             ? gas.pieces[piece + 1].start
                             : target;
      const Piece& p = gas.pieces[piece];
      const double u0 = p.level + p.slope * (t - p.start);
      advance(s1, z1, u0, p.slope, end - t);
      advance(s2, z2, u0, p.slope, end - t);
      t = end;
    }
    while (piece + 1 < gas.pieces.size() && gas.pieces[piece + 1].start <= target) ++piece;
    const Piece& now = gas.pieces[piece];
    rec.gas.push_back(now.level + now.slope * (target - now.start));
    rec.t1.push_back(z1.back() + noise * normal());
    rec.t2.push_back(z2.back() + noise * normal());
    while (next_jump < gas.jumps.size() && gas.jumps[next_jump] <= target - 2.0 * ts) ++next_jump;
    rec.near_jump.push_back(next_jump < gas.jumps.size() &&
                            gas.jumps[next_jump] <= target + 2.0 * ts);
  }
  return rec;
}

// Steps of 100-300 K (random sign) every 30-60 s, off the sample grid (issue 7's case).
Gas steps(double duration, std::uint32_t seed) {
  std::mt19937 engine(seed);
  auto uniform = [&engine](double lo, double hi) {
    return lo + (hi - lo) * (double(engine()) + 0.5) / 4294967296.0;
  };
  Gas gas;
  double level = 400.0;
  gas.pieces.push_back({0.0, level, 0.0});
  double t = uniform(30.0, 60.0);
  while (t < duration) {
    const double size = uniform(100.0, 300.0);
    level += (level > 500.0 ? -size : level < 300.0 ? size : (engine() & 1u ? size : -size));
    gas.pieces.push_back({t, level, 0.0});
    gas.jumps.push_back(t);
    t += uniform(30.0, 60.0);
  }
  return gas;
}

// Continuous piecewise-linear wander within +/-5 K around 300 K (knots every 5-20 s).
Gas wander(double duration, std::uint32_t seed) {
  std::mt19937 engine(seed);
  auto uniform = [&engine](double lo, double hi) {
    return lo + (hi - lo) * (double(engine()) + 0.5) / 4294967296.0;
  };
  Gas gas;
  double t = 0.0;
  double level = 300.0;
  while (t < duration) {
    const double next_t = t + uniform(5.0, 20.0);
    const double next_level = 300.0 + uniform(-5.0, 5.0);
    gas.pieces.push_back({t, level, (next_level - level) / (next_t - t)});
    t = next_t;
    level = next_level;
  }
  return gas;
}

const Sensor kFast{{12.48}};           // 1.5 mm Pt-100 (paper, Table I)
const Sensor kSlow{{28.95}};           // 4.5 mm Pt-100
const Sensor kFast2{{12.30, 0.17}};    // second-order fits (Table II)
const Sensor kSlow2{{25.72, 1.08}};

template <typename S>
KalmanConfig<S> config_for(const Sensor& s1, const Sensor& s2, double ts, double sigma, double q,
                           GasModel gas = GasModel::random_walk) {
  KalmanConfig<S> c;
  c.sample_interval = S(ts);
  c.gas = gas;
  c.order1 = int(s1.taus.size());
  c.order2 = int(s2.taus.size());
  for (std::size_t i = 0; i < s1.taus.size(); ++i) c.taus1[i] = S(s1.taus[i]);
  for (std::size_t i = 0; i < s2.taus.size(); ++i) c.taus2[i] = S(s2.taus[i]);
  c.taus1_cool[0] = S(s1.tau_cool);
  c.taus2_cool[0] = S(s2.tau_cool);
  c.sigma1 = S(sigma);
  c.sigma2 = S(sigma);
  c.intensity = S(q);
  return c;
}

template <typename S, int N = 6, int M = 1>
std::vector<double> reconstruct(const KalmanConfig<S>& config, const Record& rec,
                                std::vector<double>* variance = nullptr,
                                std::vector<dualprobe::KalmanJump<S>>* jumps = nullptr) {
  KalmanReconstructor<S, N, M> filter;
  EXPECT_EQ(filter.configure(config), Status::ok);
  std::vector<double> out;
  for (std::size_t k = 0; k < rec.t1.size(); ++k) {
    S gas = S(0);
    EXPECT_EQ(filter.update(S(rec.t1[k]), S(rec.t2[k]), &gas), Status::ok);
    out.push_back(double(gas));
    if (variance != nullptr) variance->push_back(double(filter.gas_variance()));
    if (jumps != nullptr && filter.jump_detected()) jumps->push_back(filter.last_jump());
  }
  return out;
}

// RMSE against the truth, samples beside a jump excluded.
double rmse(const std::vector<double>& x, const Record& rec) {
  double sum = 0.0;
  std::size_t count = 0;
  for (std::size_t k = 0; k < x.size(); ++k) {
    if (rec.near_jump[k]) continue;
    sum += (x[k] - rec.gas[k]) * (x[k] - rec.gas[k]);
    ++count;
  }
  return std::sqrt(sum / double(count));
}

template <typename T>
class KalmanTyped : public ::testing::Test {};
using Scalars = ::testing::Types<float, double>;
TYPED_TEST_SUITE(KalmanTyped, Scalars);

// ---- discretisation ------------------------------------------------------------------------

TEST(KalmanDiscretisation, FirstOrderPairMatchesClosedForm) {
  // Random-walk gas and two first-order stages: Phi and Qunit in closed form,
  // v(s) = Phi(s) e_0 = [1, 1 - exp(-s/tau1), 1 - exp(-s/tau2)], Q = int_0^Ts v v^T ds.
  for (double ts : {0.01, 0.1, 5.0, 200.0}) {  // 200 s: ~9 doublings of the scaled series
    const double tau[2] = {12.48, 28.95};
    const double q = 0.3;
    KalmanReconstructor<double, 3> filter;
    ASSERT_EQ(filter.configure(config_for<double>(kFast, kSlow, ts, 0.1, q)), Status::ok);
    const auto& phi = filter.transition(0);
    const auto& process = filter.process_noise(0);
    auto expm1_neg = [](double x) { return -std::expm1(-x); };  // 1 - exp(-x)
    double qunit[3][3];
    qunit[0][0] = ts;
    for (int i = 0; i < 2; ++i) {
      const double t = tau[i];
      qunit[0][i + 1] = qunit[i + 1][0] = ts - t * expm1_neg(ts / t);
      qunit[i + 1][i + 1] = ts - 2.0 * t * expm1_neg(ts / t) + 0.5 * t * expm1_neg(2.0 * ts / t);
    }
    const double t12 = 1.0 / (1.0 / tau[0] + 1.0 / tau[1]);
    qunit[1][2] = qunit[2][1] = ts - tau[0] * expm1_neg(ts / tau[0]) -
                                tau[1] * expm1_neg(ts / tau[1]) + t12 * expm1_neg(ts / t12);
    for (int i = 0; i < 2; ++i) {
      // Phi: gas held by the random walk, stage i relaxes towards it.
      // A few ulp per doubling (9 of them at Ts = 200 s).
      EXPECT_NEAR(phi(i + 1, i + 1), std::exp(-ts / tau[i]), 1e-14);
      EXPECT_NEAR(phi(i + 1, 0), expm1_neg(ts / tau[i]), 1e-14);
      EXPECT_EQ(phi(0, i + 1), 0.0);
    }
    EXPECT_NEAR(phi(0, 0), 1.0, 1e-14);
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        double expected = q * qunit[i][j];
        if (i == j && i > 0) {  // the floor: 1e-8 sigma^2 + q Ts (Ts/tau)^2 / 12
          const double ratio = ts / tau[i - 1];
          expected += 1e-8 * 0.01 + q * ts * ratio * ratio / 12.0;
        }
        // The closed form cancels for small Ts/tau (Qii ~ Ts^3 / tau^2): 1e-16 Ts / Qii
        // relative at worst, ~1e-9 at Ts = 0.01 s; 1e-8 relative bounds both sides.
        EXPECT_NEAR(process(i, j), expected, 1e-8 * std::abs(expected) + 1e-300)
            << "ts " << ts << " entry " << i << "," << j;
      }
    }
  }
}

TEST(KalmanDiscretisation, IntegratedRandomWalkAndCascadeAndHysteresis) {
  const double ts = 0.1;
  // irw: the gas block is [[1, Ts], [0, 1]] with Qunit [[Ts^3/3, Ts^2/2], [Ts^2/2, Ts]].
  KalmanReconstructor<double, 6> irw;
  ASSERT_EQ(irw.configure(config_for<double>(kFast2, kSlow2, ts, 0.1, 1.0,
                                             GasModel::integrated_random_walk)),
            Status::ok);
  EXPECT_EQ(irw.states(), 6);
  EXPECT_NEAR(irw.transition(0)(0, 1), ts, 1e-16);
  EXPECT_NEAR(irw.transition(0)(1, 1), 1.0, 1e-15);
  EXPECT_NEAR(irw.process_noise(0)(0, 0), ts * ts * ts / 3.0, 1e-18);
  EXPECT_NEAR(irw.process_noise(0)(0, 1), ts * ts / 2.0, 1e-17);
  EXPECT_NEAR(irw.process_noise(0)(1, 1), ts, 1e-16);
  // Two stages a -> b of sensor 1 (states 2, 3): the second stage's response to the first
  // stage's initial value is a/(a - b) (exp(-Ts/a) - exp(-Ts/b)).
  const double a = 12.30;
  const double b = 0.17;
  EXPECT_NEAR(irw.transition(0)(3, 2), a / (a - b) * (std::exp(-ts / a) - std::exp(-ts / b)),
              1e-14);
  EXPECT_NEAR(irw.transition(0)(3, 3), std::exp(-ts / b), 1e-15);
  // Hysteresis: mode bit j switches stage j to its cooling time constant.
  Sensor hot{{21.96}, 28.86};
  KalmanReconstructor<double, 3, 4> hyst;
  ASSERT_EQ(hyst.configure(config_for<double>(hot, kSlow, ts, 0.1, 1e-3)), Status::ok);
  EXPECT_EQ(hyst.modes(), 4);
  EXPECT_NEAR(hyst.transition(0)(1, 1), std::exp(-ts / 21.96), 1e-15);
  EXPECT_NEAR(hyst.transition(1)(1, 1), std::exp(-ts / 28.86), 1e-15);
  EXPECT_NEAR(hyst.transition(1)(2, 2), std::exp(-ts / 28.95), 1e-15);
}

// ---- physics -------------------------------------------------------------------------------

TYPED_TEST(KalmanTyped, StepsFarBetterThanTheSensor) {
  using S = TypeParam;
  // Issue 7: 10 Hz Pt-100 pair, 0.1 K noise, steps of 100-300 K off the sample grid.
  const Record rec = simulate(steps(600.0, 11u), kFast, kSlow, 0.1, 6001, 0.1, 5u);
  std::vector<dualprobe::KalmanJump<S>> found;
  const auto gas =
      reconstruct<S, 3>(config_for<S>(kFast, kSlow, 0.1, 0.1, 1e-4), rec, nullptr, &found);
  const double ratio = rmse(gas, rec) / rmse(rec.t1, rec);
  // The issue asks <= 6 % (aim 2 %); the reference measures 0.9-1.3 %; 3 % leaves margin
  // for other noise draws while catching a regression.
  EXPECT_LT(ratio, 0.03) << "RMSE ratio " << ratio;
  // Every step found within a sample interval of its time (interval theta spans
  // t_(theta-1)..t_theta, the fraction places it inside; a step just after t_theta may be put
  // at the end of theta), declared at most 3 samples later; a second detection right after
  // the first may refine the size (as in the reference); no detection away from a step.
  auto when = [&rec](const dualprobe::KalmanJump<S>& j) {
    return (double(j.interval) - 1.0 + double(j.fraction)) * rec.ts;
  };
  for (double jump : rec.jumps) {
    bool located = false;
    for (const auto& j : found) {
      located = located || (std::abs(when(j) - jump) < rec.ts &&
                            double(j.detected_at) * rec.ts - jump < 3.0 * rec.ts);
    }
    EXPECT_TRUE(located) << "step at " << jump << " s not located";
  }
  for (const auto& j : found) {
    double nearest = 1e300;
    for (double jump : rec.jumps) nearest = std::min(nearest, std::abs(jump - when(j)));
    EXPECT_LT(nearest, 3.0 * rec.ts) << "false alarm in interval " << j.interval;
  }
}

TYPED_TEST(KalmanTyped, SecondOrderSensorsAndSmallMotion) {
  using S = TypeParam;
  // Second-order sensors on steps: measured 4 % of the sensor's RMSE in the reference.
  const Record rec = simulate(steps(400.0, 3u), kFast2, kSlow2, 0.1, 4001, 0.1, 9u);
  const auto gas = reconstruct<S, 5>(config_for<S>(kFast2, kSlow2, 0.1, 0.1, 1e-4), rec);
  EXPECT_LT(rmse(gas, rec) / rmse(rec.t1, rec), 0.1);
  // +/-5 K wander, integrated random walk: the sensor lags by ~slope tau; the filter follows.
  // Intensity from the profile's statistics (what the smoother identifies from the data): the
  // slope changes at each knot by the difference of two slopes (level difference of variance
  // 2 x 10^2/12 over a hold of E[1/dt^2] = 0.01 s^-2), once per 12.5 s on average.
  const double q = 2.0 * (2.0 * 100.0 / 12.0 * 0.01) / 12.5;  // ~0.027 K^2/s^3
  const Record small = simulate(wander(600.0, 4u), kFast, kSlow, 0.1, 6001, 0.1, 2u);
  const auto irw = reconstruct<S, 4>(
      config_for<S>(kFast, kSlow, 0.1, 0.1, q, GasModel::integrated_random_walk), small);
  const double ratio = rmse(irw, small) / rmse(small.t1, small);
  EXPECT_LT(ratio, 0.35) << ratio;  // the bound for this case (measured 0.30)
}

TYPED_TEST(KalmanTyped, HysteresisModelBeatsTheLinearOne) {
  using S = TypeParam;
  // The 1.5 mm probe heats with 21.96 s and cools with 28.86 s (paper); a linear model with
  // the heating constant mistakes every cooling transient for gas motion.
  const Sensor hot{{21.96}, 28.86};
  const Record rec = simulate(steps(600.0, 21u), hot, kSlow, 0.1, 6001, 0.1, 4u);
  Sensor linear = hot;
  linear.tau_cool = 0.0;
  const auto aware = reconstruct<S, 3, 4>(config_for<S>(hot, kSlow, 0.1, 0.1, 1e-4), rec);
  const auto plain = reconstruct<S, 3, 4>(config_for<S>(linear, kSlow, 0.1, 0.1, 1e-4), rec);
  const double sensor = rmse(rec.t1, rec);
  EXPECT_LT(rmse(aware, rec), 0.5 * rmse(plain, rec));
  EXPECT_LT(rmse(aware, rec) / sensor, 0.05);
}

TEST(KalmanPrecision, FloatFollowsDouble) {
  // Float rounding of states of ~1e2 K, amplified at start-up and at each detected jump
  // (where the filter's own uncertainty is largest), stays a small fraction of that
  // uncertainty: bound 0.05 of the double filter's gas standard deviation plus 1e-3 K.
  for (const auto& sensors : {std::make_pair(kFast, kSlow), std::make_pair(kFast2, kSlow2)}) {
    const Record rec = simulate(steps(300.0, 8u), sensors.first, sensors.second, 0.1, 3001,
                                0.1, 6u);
    std::vector<double> variance;
    const auto d = reconstruct<double>(
        config_for<double>(sensors.first, sensors.second, 0.1, 0.1, 1e-4), rec, &variance);
    const auto f = reconstruct<float>(
        config_for<float>(sensors.first, sensors.second, 0.1, 0.1, 1e-4), rec);
    double worst = 0.0;
    double sum = 0.0;
    for (std::size_t k = 0; k < d.size(); ++k) {
      const double err = std::abs(f[k] - d[k]);
      worst = std::max(worst, err / (std::sqrt(variance[k]) + 0.02));
      sum += err * err;
    }
    EXPECT_LT(worst, 0.05);
    // Typical difference: a few 1e-4 K, against 0.1 K of sensor noise.
    EXPECT_LT(std::sqrt(sum / double(d.size())), 0.02);
  }
}

// ---- contract ------------------------------------------------------------------------------

template <typename Filter>
void expect_same_state(const Filter& a, const Filter& b) {
  EXPECT_EQ(a.samples(), b.samples());
  EXPECT_EQ(a.candidates(), b.candidates());
  EXPECT_TRUE((a.state().array() == b.state().array()).all());
  EXPECT_TRUE((a.covariance().array() == b.covariance().array()).all());
  EXPECT_EQ(a.log_likelihood(), b.log_likelihood());
}

TYPED_TEST(KalmanTyped, NonFiniteSamplesAreRefusedWithStateUntouched) {
  using S = TypeParam;
  const Record rec = simulate(steps(60.0, 1u), kFast, kSlow, 0.1, 601, 0.1, 1u);
  KalmanReconstructor<S, 3> filter;
  ASSERT_EQ(filter.configure(config_for<S>(kFast, kSlow, 0.1, 0.1, 1e-4)), Status::ok);
  S gas = S(-7);
  EXPECT_EQ(filter.update(S(1), S(2), &gas), Status::ok);  // the first sample
  filter.reset();
  for (std::size_t k = 0; k < 300; ++k) filter.update(S(rec.t1[k]), S(rec.t2[k]));
  const auto twin = filter;
  const S bad[] = {std::numeric_limits<S>::quiet_NaN(), std::numeric_limits<S>::infinity(),
                   -std::numeric_limits<S>::infinity()};
  for (S b : bad) {
    gas = S(-7);
    EXPECT_EQ(filter.update(b, S(300), &gas), Status::non_finite_input);
    EXPECT_EQ(filter.update(S(300), b, &gas), Status::non_finite_input);
    EXPECT_EQ(gas, S(-7));  // output untouched too
  }
  expect_same_state(filter, twin);
  // Before any configuration: not ready.
  KalmanReconstructor<S, 3> blank;
  EXPECT_EQ(blank.update(S(1), S(2)), Status::not_ready);
  EXPECT_EQ(blank.skip(), Status::not_ready);
}

TYPED_TEST(KalmanTyped, BadConfigurationIsRefusedAndChangesNothing) {
  using S = TypeParam;
  const Record rec = simulate(steps(80.0, 2u), kFast, kSlow, 0.1, 801, 0.1, 3u);
  const auto good = config_for<S>(kFast, kSlow, 0.1, 0.1, 1e-4);
  KalmanReconstructor<S, 3> filter;
  ASSERT_EQ(filter.configure(good), Status::ok);
  for (std::size_t k = 0; k < 400; ++k) filter.update(S(rec.t1[k]), S(rec.t2[k]));
  auto twin = filter;
  const S nan = std::numeric_limits<S>::quiet_NaN();
  std::vector<KalmanConfig<S>> bad(22, good);
  bad[0].sample_interval = S(0);
  bad[1].sample_interval = nan;
  bad[2].taus1[0] = S(-1);
  bad[3].taus2[0] = std::numeric_limits<S>::infinity();
  bad[4].sigma1 = S(0);
  bad[5].sigma2 = nan;
  bad[6].intensity = S(-1e-3);
  bad[7].intensity = nan;
  bad[8].window = 0;
  bad[9].window = 65;  // above MaxWindow
  bad[10].false_alarm = S(0);
  bad[11].false_alarm = S(1);
  bad[12].order1 = 3;
  bad[13].order2 = 0;
  bad[14].gas = static_cast<GasModel>(7);
  bad[15].taus1_cool[0] = S(-2);
  bad[16].taus1_cool[0] = S(20);  // hysteresis needs MaxModes >= 4
  bad[17].gas = GasModel::integrated_random_walk;  // 4 states > MaxStates = 3
  bad[18].order1 = 2;                               // likewise
  bad[19].taus2_cool[0] = nan;
  bad[20].intensity = std::numeric_limits<S>::max();  // q Qunit (~Ts) overflows the scalar
  bad[20].sample_interval = S(100);
  bad[21].sample_interval = std::numeric_limits<S>::infinity();
  for (std::size_t i = 0; i < bad.size(); ++i) {
    EXPECT_EQ(filter.configure(bad[i]), Status::invalid_argument) << "case " << i;
    EXPECT_EQ(filter.retune(bad[i]), Status::invalid_argument) << "case " << i;
  }
  expect_same_state(filter, twin);
  // ... and it goes on exactly as a twin that never saw them.
  for (std::size_t k = 400; k < rec.t1.size(); ++k) {
    S a = S(0);
    S b = S(0);
    ASSERT_EQ(filter.update(S(rec.t1[k]), S(rec.t2[k]), &a), Status::ok);
    ASSERT_EQ(twin.update(S(rec.t1[k]), S(rec.t2[k]), &b), Status::ok);
    ASSERT_EQ(a, b);
  }
}

TYPED_TEST(KalmanTyped, RetuneKeepsTheStateAndSkipKeepsTime) {
  using S = TypeParam;
  const Record rec = simulate(steps(200.0, 5u), kFast, kSlow, 0.1, 2001, 0.1, 8u);
  // Started with 20 % wrong time constants, retuned to the right ones at 100 s (as the ECU
  // does after the online estimator solved). A filter with a wrong model drifts kelvins away
  // (its stages disagree with the sensors); after the retune it re-converges, and from the next
  // gas step on it is the filter that had the right model all along.
  auto wrong = config_for<S>({{12.48 * 1.2}}, {{28.95 * 0.8}}, 0.1, 0.1, 1e-4);
  const auto right = config_for<S>(kFast, kSlow, 0.1, 0.1, 1e-4);
  KalmanReconstructor<S, 3> tuned;
  KalmanReconstructor<S, 3> reference;
  KalmanReconstructor<S, 3> never;
  ASSERT_EQ(tuned.configure(wrong), Status::ok);
  ASSERT_EQ(never.configure(wrong), Status::ok);
  ASSERT_EQ(reference.configure(right), Status::ok);
  double tuned_vs_reference = 0.0;
  double never_error = 0.0;
  for (std::size_t k = 0; k < rec.t1.size(); ++k) {
    if (k == 1000) {
      const auto x = tuned.state();
      const auto p = tuned.covariance();
      ASSERT_EQ(tuned.retune(right), Status::ok);
      EXPECT_TRUE((tuned.state().array() == x.array()).all());  // state and covariance kept
      EXPECT_TRUE((tuned.covariance().array() == p.array()).all());
      EXPECT_TRUE((tuned.transition(0).array() == reference.transition(0).array()).all());
      EXPECT_EQ(tuned.candidates(), 0);  // evidence weighed with the old model dropped
      EXPECT_EQ(tuned.samples(), 1000u);
    }
    S a = S(0);
    S b = S(0);
    S c = S(0);
    tuned.update(S(rec.t1[k]), S(rec.t2[k]), &a);
    reference.update(S(rec.t1[k]), S(rec.t2[k]), &b);
    never.update(S(rec.t1[k]), S(rec.t2[k]), &c);
    // The record's last step is at 177.2 s; 7 s (~tau1/2) after it.
    if (k >= 1850) {
      tuned_vs_reference = std::max(tuned_vs_reference, std::abs(double(a) - double(b)));
      never_error = std::max(never_error, std::abs(double(c) - rec.gas[k]));
    }
  }
  ASSERT_NEAR(rec.jumps.back(), 177.16, 0.01);
  EXPECT_LT(tuned_vs_reference, 0.05);  // half the sensor noise (measured ~0.01 K)
  EXPECT_GT(never_error, 1.0);          // without the retune: kelvins off (measured ~5 K)
  // A different state layout cannot be retuned.
  auto second = right;
  second.order1 = 2;
  second.taus1 = {S(12.30), S(0.17)};
  EXPECT_EQ(tuned.retune(second), Status::invalid_argument);

  // skip(): a missing sample advances time. A record with 20 samples missing mid-plateau is
  // reconstructed after the gap about as well as the complete one.
  KalmanReconstructor<S, 3> gappy;
  KalmanReconstructor<S, 3> full;
  ASSERT_EQ(gappy.configure(right), Status::ok);
  ASSERT_EQ(full.configure(right), Status::ok);
  S a = S(0);
  S b = S(0);
  for (std::size_t k = 0; k < 600; ++k) {
    if (k >= 200 && k < 220) {
      EXPECT_EQ(gappy.skip(&a), Status::ok);
    } else {
      EXPECT_EQ(gappy.update(S(rec.t1[k]), S(rec.t2[k]), &a), Status::ok);
    }
    full.update(S(rec.t1[k]), S(rec.t2[k]), &b);
  }
  EXPECT_EQ(gappy.samples(), full.samples());
  EXPECT_NEAR(double(a), double(b), 0.05);  // 380 samples later, within half the noise
}

TYPED_TEST(KalmanTyped, UpdateAndConfigureDoNotAllocate) {
  using S = TypeParam;
  const Record rec = simulate(steps(120.0, 6u), kFast2, kSlow2, 0.1, 1201, 0.1, 4u);
  Sensor hot{{21.96}, 28.86};
  KalmanReconstructor<S, 6, 4> filter;
  std::vector<S> out(rec.t1.size());
  std::vector<S> t1(rec.t1.begin(), rec.t1.end());
  std::vector<S> t2(rec.t2.begin(), rec.t2.end());
  t1[50] = std::numeric_limits<S>::quiet_NaN();  // a refused sample: skip() inside the block
  Eigen::internal::set_is_malloc_allowed(false);
  const Status first = filter.configure(config_for<S>(kFast2, kSlow2, 0.1, 0.1, 1e-4,
                                                      GasModel::integrated_random_walk));
  const std::size_t refused = filter.update_block(t1.data(), t2.data(), t1.size(), out.data());
  const Status second = filter.configure(config_for<S>(hot, kSlow, 0.1, 0.1, 1e-4));
  for (std::size_t k = 0; k < rec.t1.size(); ++k) filter.update(t1[k], t2[k]);
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_EQ(first, Status::ok);
  EXPECT_EQ(second, Status::ok);
  EXPECT_EQ(refused, 1u);
  EXPECT_TRUE(std::isnan(out[50]));
  EXPECT_TRUE(std::isfinite(out[51]));
}

TEST(KalmanMemory, SizesAreFixedByTheTemplate) {
  // GLR window 64 x (2 n + 5) scalars dominates; see the report for every configuration.
  EXPECT_LE(sizeof(dualprobe::KalmanFirstOrder<float>), 3584u);
  EXPECT_LE(sizeof(dualprobe::KalmanFull<double>), 12288u);
  std::printf("sizeof: first-order float %zu, double %zu; full (6 states) float %zu, double %zu; "
              "full + 16 modes float %zu\n",
              sizeof(dualprobe::KalmanFirstOrder<float>),
              sizeof(dualprobe::KalmanFirstOrder<double>), sizeof(dualprobe::KalmanFull<float>),
              sizeof(dualprobe::KalmanFull<double>),
              sizeof(dualprobe::KalmanReconstructor<float, 6, 16>));
}

// ---- float soak ----------------------------------------------------------------------------

TEST(KalmanSoak, LongFloatRunStaysFiniteSymmetricPositiveDefiniteAndAccurate) {
#if defined(NDEBUG) && !defined(__SANITIZE_ADDRESS__)
  const std::size_t n = 2000000;  // 5.6 h at 100 Hz
#else
  const std::size_t n = 100000;  // unoptimised / sanitised builds
#endif
  // 100 Hz thin-film pair (the firmware's 1.248 s / 2.895 s), steps and wander, 0.02 K noise.
  const double ts = 0.01;
  const double duration = double(n) * ts;
  // Steps with a +/-5 K wander on top (both piecewise affine: merge the breaks).
  const Gas jumps = steps(duration, 31u);
  const Gas small = wander(duration, 32u);
  Gas both;
  both.jumps = jumps.jumps;
  {
    std::size_t i = 0;
    std::size_t j = 0;
    while (i < jumps.pieces.size() || j < small.pieces.size()) {
      const bool take_step = j == small.pieces.size() ||
                             (i < jumps.pieces.size() && jumps.pieces[i].start <= small.pieces[j].start);
      const double t = take_step ? jumps.pieces[i].start : small.pieces[j].start;
      if (take_step) ++i; else ++j;
      if (!both.pieces.empty() && both.pieces.back().start == t) both.pieces.pop_back();
      const Piece& w = small.pieces[j == 0 ? 0 : j - 1];  // the wander piece in force at t
      const Piece& g = jumps.pieces[i == 0 ? 0 : i - 1];
      both.pieces.push_back({t, g.level + w.level + w.slope * (t - w.start) - 300.0, w.slope});
    }
  }
  const Sensor fast{{1.248}};
  const Sensor slow{{2.895}};
  const Record rec = simulate(both, fast, slow, ts, n, 0.02, 12u);
  KalmanReconstructor<float, 3> filter;
  ASSERT_EQ(filter.configure(config_for<float>(fast, slow, ts, 0.02, 1e-2)), Status::ok);
  double first = 0.0;
  double last = 0.0;
  std::size_t first_count = 0;
  std::size_t last_count = 0;
  double sensor = 0.0;
  const std::size_t segment = n / 10;
  for (std::size_t k = 0; k < n; ++k) {
    float out = 0.0f;
    ASSERT_EQ(filter.update(float(rec.t1[k]), float(rec.t2[k]), &out), Status::ok) << k;
    ASSERT_TRUE(std::isfinite(out)) << k;
    if (k % 4096 == 0) {
      const auto& p = filter.covariance();
      ASSERT_TRUE((p.array() == p.transpose().array()).all()) << k;  // exactly symmetric
      Eigen::LLT<Eigen::Matrix3f> llt(p);
      ASSERT_EQ(llt.info(), Eigen::Success) << "lost positive definiteness at " << k;
    }
    if (rec.near_jump[k]) continue;
    const double err = (double(out) - rec.gas[k]) * (double(out) - rec.gas[k]);
    if (k >= 1000 && k < segment) {
      first += err;
      ++first_count;
    } else if (k >= n - segment) {
      last += err;
      sensor += (rec.t1[k] - rec.gas[k]) * (rec.t1[k] - rec.gas[k]);
      ++last_count;
    }
  }
  const double rmse_first = std::sqrt(first / double(first_count));
  const double rmse_last = std::sqrt(last / double(last_count));
  const double sensor_last = std::sqrt(sensor / double(last_count));
  std::printf("soak: %zu float updates, RMSE first tenth %.4f K, last tenth %.4f K, sensor %.4f K\n",
              n, rmse_first, rmse_last, sensor_last);
  // No drift: the last tenth is as accurate as the first (same statistics; 1.5x allows for
  // the different steps and wander in the two segments).
  EXPECT_LT(rmse_last, 1.5 * rmse_first) << rmse_first << " " << rmse_last;
  // Far better than the sensor on the same samples (issue 7: <= 35 % on +/-5 K motion).
  EXPECT_LT(rmse_last, 0.35 * sensor_last) << sensor_last;
}

}  // namespace
