// The fixed-lag output of the Kalman reconstruction (kalman.hpp, MaxLag > 0): against an
// independent Rauch-Tung-Striebel smoother written here, run on the same filter's filtered
// states over the data up to t_k (the fixed-lag estimate of t_{k-L} is, by definition, that
// smoother's value at k - L), for constant and per-sample (scheduled) models; float against
// double;
// its accuracy against the true gas; and its contract (capacity, not ready, reset, retune).
#define EIGEN_RUNTIME_NO_MALLOC
#include <gtest/gtest.h>

#include <Eigen/LU>
#include <cmath>
#include <algorithm>
#include <cstdint>
#include <random>
#include <vector>

#include "dualprobe/kalman.hpp"

namespace {

using dualprobe::KalmanConfig;
using dualprobe::KalmanReconstructor;
using dualprobe::Status;

constexpr int kLag = 12;
template <typename S>
using Filter = KalmanReconstructor<S, 5, 1, 8, kLag>;

// A pair of second-order sensors (element, sheath) following a gas of a few sines plus a
// ramp, integrated on a 20x finer grid (Euler on a grid 1/20 of the shortest stage: a richer
// signal than the filter's piecewise-constant random walk), plus white noise.
struct Data {
  double ts = 0.01;
  std::vector<double> gas, t1, t2, psi;
};

Data simulate(std::size_t n, double noise, bool scheduled, std::uint32_t seed) {
  Data d;
  const double taus[2][2] = {{1.2, 0.15}, {3.0, 0.3}};
  double z[2][2] = {{500, 500}, {500, 500}};
  std::mt19937 engine(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  const int sub = 20;
  const double h = d.ts / sub;
  auto gas_at = [](double t) {
    return 500.0 + 30.0 * std::sin(0.4 * t) + 8.0 * std::sin(2.1 * t + 1.0) +
           2.0 * std::sin(6.0 * t + 0.3) + 1.5 * t;
  };
  auto psi_at = [scheduled](double t) { return scheduled ? 1.0 + 0.6 * std::sin(0.7 * t) : 1.0; };
  for (std::size_t k = 0; k < n; ++k) {
    const double t = double(k) * d.ts;
    if (k > 0) {
      for (int s = 0; s < sub; ++s) {
        const double tt = t - d.ts + (s + 0.5) * h;
        const double g = gas_at(tt);
        const double p = psi_at(tt);
        for (int i = 0; i < 2; ++i) {
          z[i][0] += h * p * (g - z[i][0]) / taus[i][1];        // sheath
          z[i][1] += h * p * (z[i][0] - z[i][1]) / taus[i][0];  // element
        }
      }
    }
    d.gas.push_back(gas_at(t));
    d.psi.push_back(psi_at(t));
    d.t1.push_back(z[0][1] + noise * normal(engine));
    d.t2.push_back(z[1][1] + noise * normal(engine));
  }
  return d;
}

template <typename S>
KalmanConfig<S> config(int lag, bool jumps) {
  KalmanConfig<S> c;
  c.sample_interval = S(0.01);
  c.order1 = 2;
  c.order2 = 2;
  c.taus1 = {{S(0.15), S(1.2)}};  // the chain's input stage first: sheath, then element
  c.taus2 = {{S(0.3), S(3.0)}};
  c.sigma1 = S(0.02);
  c.sigma2 = S(0.02);
  c.intensity = S(20);
  c.detect_jumps = jumps;
  c.window = 8;
  c.lag = lag;
  return c;
}

// The model of one interval with time constants tau / psi (Euler-free: the core's own exact
// discretisation of a configured twin, so that the smoother below sees the filter's model).
template <typename S>
void model_at(double psi, const KalmanConfig<S>& base, typename Filter<S>::Matrix* phi,
              typename Filter<S>::Matrix* q) {
  KalmanConfig<S> c = base;
  for (int j = 0; j < 2; ++j) {
    c.taus1[j] = S(double(base.taus1[j]) / psi);
    c.taus2[j] = S(double(base.taus2[j]) / psi);
  }
  Filter<S> twin;
  EXPECT_EQ(twin.configure(c), Status::ok);
  *phi = twin.transition(0);
  *q = twin.process_noise(0);
}

// Sample k into a scheduled filter: the interval's model (from psi at k - 1), then the update.
template <typename S>
::testing::AssertionResult scheduled_update(Filter<S>& f, const KalmanConfig<S>& c,
                                            const Data& d, std::size_t k, S* gas) {
  if (k > 0) {
    typename Filter<S>::Matrix phi, q;
    model_at<S>(d.psi[k - 1], c, &phi, &q);
    if (f.set_model(phi, q) != Status::ok) return ::testing::AssertionFailure() << "set_model";
  }
  if (f.update(S(d.t1[k]), S(d.t2[k]), gas) != Status::ok) {
    return ::testing::AssertionFailure() << "update at " << k;
  }
  return ::testing::AssertionSuccess();
}

// Runs the filter, storing every filtered state and covariance and every interval's model; at
// each k >= L compares the filter's lagged output with an RTS pass from k back to k - L.
template <typename S>
void check_against_rts(bool scheduled, double tol) {
  const Data d = simulate(3000, 0.02, scheduled, 7);
  const KalmanConfig<S> c = config<S>(kLag, false);
  Filter<S> f;
  ASSERT_EQ(f.configure(c), Status::ok);
  using Matrix = Eigen::Matrix<double, 5, 5>;
  using Vector = Eigen::Matrix<double, 5, 1>;
  std::vector<Vector> xf;
  std::vector<Matrix> pf;
  std::vector<Matrix> phis(1, Matrix::Identity());
  std::vector<Matrix> qs(1, Matrix::Zero());
  double worst = 0.0;
  double worst_sd = 0.0;
  for (std::size_t k = 0; k < d.gas.size(); ++k) {
    if (k > 0) {
      typename Filter<S>::Matrix phi, q;
      model_at<S>(d.psi[k - 1], c, &phi, &q);
      if (scheduled) {
        ASSERT_EQ(f.set_model(phi, q), Status::ok);
      }
      phis.push_back(phi.template cast<double>());
      qs.push_back(q.template cast<double>());
    }
    S gas = 0;
    ASSERT_EQ(f.update(S(d.t1[k]), S(d.t2[k]), &gas), Status::ok);
    xf.push_back(f.state().template cast<double>());
    pf.push_back(f.covariance().template cast<double>());
    S lagged = 0;
    S variance = 0;
    const bool ready = f.lagged(&lagged, &variance);
    ASSERT_EQ(ready, k >= std::size_t(kLag)) << k;
    if (!ready || k < 200) continue;  // RTS from the first samples: the spread-out start
    // RTS: xs_j = xf_j + G_j (xs_{j+1} - Phi_{j+1} xf_j), Ps likewise, G_j = Pf_j Phi^T Pp^-1.
    Vector xs = xf[k];
    Matrix ps = pf[k];
    for (std::size_t j = k; j-- > k - kLag;) {
      const Matrix& phi = phis[j + 1];
      const Matrix pp = phi * pf[j] * phi.transpose() + qs[j + 1];
      const Matrix g = pf[j] * phi.transpose() * pp.inverse();
      xs = xf[j] + g * (xs - phi * xf[j]);
      ps = pf[j] + g * (ps - pp) * g.transpose();
    }
    worst = std::max(worst, std::abs(double(lagged) - xs[0]));
    worst_sd = std::max(worst_sd, std::abs(std::sqrt(double(variance)) - std::sqrt(ps(0, 0))));
  }
  EXPECT_LT(worst, tol);
  EXPECT_LT(worst_sd, tol);
}

// The two are the same algebra (fixed-lag = RTS on the truncated record), so in double they
// agree to rounding of a few hundred steps of 5 x 5 products (1e-8 K is ~1e4 ulp at 500 K).
TEST(KalmanFixedLag, EqualsRtsOnTheTruncatedRecordDouble) { check_against_rts<double>(false, 1e-8); }
TEST(KalmanFixedLag, EqualsRtsScheduledDouble) { check_against_rts<double>(true, 1e-8); }

// Float: the lagged output adds no rounding growth of its own. Its distance to the double
// lagged output stays within twice the float filter's own distance to the double filter
// (measured here: 1.7e-3 K lagged, 2.0e-3 K filtered: float's resolution around 500 K, 3e-5 K,
// amplified by the inverse problem).
TEST(KalmanFixedLag, FloatRoundsNoWorseThanTheFilter) {
  const Data d = simulate(3000, 0.02, true, 7);
  const KalmanConfig<float> cf = config<float>(kLag, false);
  const KalmanConfig<double> cd = config<double>(kLag, false);
  Filter<float> ff;
  Filter<double> fd;
  ASSERT_EQ(ff.configure(cf), Status::ok);
  ASSERT_EQ(fd.configure(cd), Status::ok);
  double filtered = 0.0;
  double lagged = 0.0;
  for (std::size_t k = 0; k < d.gas.size(); ++k) {
    float gf = 0.0f;
    double gd = 0.0;
    ASSERT_TRUE(scheduled_update(ff, cf, d, k, &gf));
    ASSERT_TRUE(scheduled_update(fd, cd, d, k, &gd));
    float lf = 0.0f;
    double ld = 0.0;
    if (k < 200 || !ff.lagged(&lf, nullptr) || !fd.lagged(&ld, nullptr)) continue;
    filtered = std::max(filtered, std::abs(double(gf) - gd));
    lagged = std::max(lagged, std::abs(double(lf) - ld));
  }
  EXPECT_GT(filtered, 0.0);
  EXPECT_LE(lagged, 2.0 * filtered) << "filtered " << filtered;
}

// Known truth: the lagged estimate of t_{k-L} is closer to the true gas than the causal
// estimate of t_k (measured: 0.47 K against 1.73 K, 3.7x; 2x is the bar, left for other seeds).
TEST(KalmanFixedLag, CloserToTheTruthThanTheFilter) {
  const Data d = simulate(6000, 0.02, true, 11);
  const KalmanConfig<double> c = config<double>(kLag, false);
  Filter<double> f;
  ASSERT_EQ(f.configure(c), Status::ok);
  double causal = 0.0;
  double lagged = 0.0;
  int count = 0;
  for (std::size_t k = 0; k < d.gas.size(); ++k) {
    double gas = 0.0;
    ASSERT_TRUE(scheduled_update(f, c, d, k, &gas));
    double back = 0.0;
    if (k < 1000 || !f.lagged(&back, nullptr)) continue;
    causal += (gas - d.gas[k]) * (gas - d.gas[k]);
    lagged += (back - d.gas[k - kLag]) * (back - d.gas[k - kLag]);
    ++count;
  }
  const double rc = std::sqrt(causal / count);
  const double rl = std::sqrt(lagged / count);
  EXPECT_LT(rl, 0.5 * rc) << "causal " << rc << " lagged " << rl;
}

TEST(KalmanFixedLag, Contract) {
  Filter<float> f;
  KalmanConfig<float> c = config<float>(kLag + 1, false);
  EXPECT_EQ(f.configure(c), Status::invalid_argument);  // beyond the capacity
  c.lag = -1;
  EXPECT_EQ(f.configure(c), Status::invalid_argument);
  c = config<float>(3, true);  // a lag with jump detection: refused (kalman.hpp)
  EXPECT_EQ(f.configure(c), Status::invalid_argument);
  c.detect_jumps = false;
  c.lag = 3;
  ASSERT_EQ(f.configure(c), Status::ok);
  float gas = 0.0f;
  float var = 0.0f;
  EXPECT_FALSE(f.lagged(&gas, &var));  // nothing yet
  for (int k = 0; k < 3; ++k) {
    ASSERT_EQ(f.update(500.0f, 500.0f), Status::ok);
    EXPECT_FALSE(f.lagged(&gas, &var)) << k;  // t_{k-3} not seen yet
  }
  ASSERT_EQ(f.update(500.0f, 500.0f), Status::ok);
  EXPECT_TRUE(f.lagged(&gas, &var));
  EXPECT_NEAR(gas, 500.0f, 1e-3f);
  EXPECT_GE(var, 0.0f);
  f.reset();
  EXPECT_FALSE(f.lagged(&gas, &var));
  // lag 0: the filtered gas itself.
  c.lag = 0;
  ASSERT_EQ(f.configure(c), Status::ok);
  float filtered = 0.0f;
  ASSERT_EQ(f.update(501.0f, 499.0f, &filtered), Status::ok);
  ASSERT_TRUE(f.lagged(&gas, &var));
  EXPECT_EQ(gas, filtered);
  EXPECT_EQ(var, f.gas_variance());
}

}  // namespace
