// Proves that update() and solve() never touch the heap: Eigen asserts on any allocation while
// malloc is disallowed, and a replaced global operator new counts C++ allocations.
#define EIGEN_RUNTIME_NO_MALLOC
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <new>

#include "dualprobe/dualprobe.hpp"
#include "test_support.hpp"

namespace {
std::atomic<long> g_allocations{0};
}  // namespace

void* operator new(std::size_t size) {
  g_allocations.fetch_add(1);
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

namespace {

template <typename T>
class NoHeapTest : public ::testing::Test {};
using Scalars = ::testing::Types<float, double>;
TYPED_TEST_SUITE(NoHeapTest, Scalars);

TYPED_TEST(NoHeapTest, UpdateAndSolveDoNotAllocate) {
  using S = TypeParam;
  const auto series = dualprobe::test::difference_equation_pair(300, 12.48, 28.95, 1.0);
  for (auto method : {dualprobe::Method::ls, dualprobe::Method::tls, dualprobe::Method::gtls}) {
    dualprobe::DifferenceEstimator<S> estimator;
    dualprobe::DifferenceConfig<S> config;
    config.method = method;
    config.sigma1 = S(0.05);
    config.sigma2 = S(0.05);
    config.forgetting = S(0.999);
    ASSERT_EQ(estimator.configure(config), dualprobe::Status::ok);
    const long before = g_allocations.load();
    Eigen::internal::set_is_malloc_allowed(false);
    for (std::size_t k = 0; k < series.t1.size(); ++k) {
      estimator.update(S(series.t1[k]), S(series.t2[k]));
    }
    const auto result = estimator.solve();
    Eigen::internal::set_is_malloc_allowed(true);
    EXPECT_EQ(g_allocations.load(), before);
    EXPECT_EQ(result.status, dualprobe::Status::ok);
  }
}

TYPED_TEST(NoHeapTest, ScheduledSvfUpdateSolveAndMomentsDoNotAllocate) {
  // The flow-scheduled SVF (design.md 1.5): Basis 1 (the ECU variants) and the affine split.
  using S = TypeParam;
  const auto series = dualprobe::test::difference_equation_pair(3000, 12.48, 28.95, 0.1);
  dualprobe::SvfConfig<S> config;
  config.sample_interval = S(0.1);
  config.filter_time_constant = S(2.0);
  config.sigma1 = S(0.05);
  config.sigma2 = S(0.05);
  config.direction_half_window1 = 5;
  config.direction_half_window2 = 5;
  dualprobe::SvfScheduled<S, 1> first;
  dualprobe::SvfScheduled<S, 2> second;
  dualprobe::SvfScheduledHysteresis<S, dualprobe::StaticModel::affine> split;
  ASSERT_EQ(first.configure(config), dualprobe::Status::ok);
  ASSERT_EQ(second.configure(config), dualprobe::Status::ok);
  ASSERT_EQ(split.configure(config), dualprobe::Status::ok);
  const long before = g_allocations.load();
  Eigen::internal::set_is_malloc_allowed(false);
  for (std::size_t k = 0; k < series.t1.size(); ++k) {
    const S psi = S(1.0 + 0.3 * std::sin(0.001 * double(k)));
    first.update(S(series.t1[k]), S(series.t2[k]), psi);
    second.update(S(series.t1[k]), S(series.t2[k]), &psi, S(1) / psi);
    split.update(S(series.t1[k]), S(series.t2[k]), psi);
  }
  const auto a = first.solve();
  const auto b = second.solve(second.moments());
  const auto c = split.solve();
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_EQ(g_allocations.load(), before);
  EXPECT_NE(a.status, dualprobe::Status::not_ready);
  EXPECT_NE(b.status, dualprobe::Status::not_ready);
  EXPECT_NE(c.status, dualprobe::Status::not_ready);
}

TEST(NoHeap, EstimatorSizeIsFixedAndSmall) {
  // Issue 4's ECU budget; the header also static_asserts it.
  EXPECT_LE(sizeof(dualprobe::DifferenceEstimator<float>), 128u);
}

}  // namespace
