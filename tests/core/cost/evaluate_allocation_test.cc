// Checks that SparseSurfaceCost::Evaluate allocates nothing in steady state, by interposing malloc
// (glibc: every operator new and every Eigen allocation goes through malloc, realloc or calloc).
// The counters are off except inside the measured region, so the rest of the test binary is
// unaffected.
#include <gtest/gtest.h>

#include <atomic>
#include <cstddef>

#include "core/cost/sparse_surface_cost.h"
#include "tests/core/cost/cost_test_util.h"

#if defined(__GLIBC__)
namespace {
std::atomic<bool> counting{false};
std::atomic<long> allocations{0};
void Count() {
  if (counting.load(std::memory_order_relaxed)) allocations.fetch_add(1, std::memory_order_relaxed);
}
}  // namespace

extern "C" {
void* __libc_malloc(std::size_t size);
void* __libc_realloc(void* pointer, std::size_t size);
void* __libc_calloc(std::size_t count, std::size_t size);
void* malloc(std::size_t size) {
  Count();
  return __libc_malloc(size);
}
void* realloc(void* pointer, std::size_t size) {
  Count();
  return __libc_realloc(pointer, size);
}
void* calloc(std::size_t count, std::size_t size) {
  Count();
  return __libc_calloc(count, size);
}
}
#endif

namespace softid::cost {
namespace {

using testing::MakeTorusScene;
using testing::SampleOnNodes;
using testing::Scene;

// After a first call has sized the scratch storage, further calls with the same sizes allocate
// nothing, with and without gradient and matches.
TEST(SparseSurfaceCost, EvaluateDoesNotAllocateInSteadyState) {
#if !defined(__GLIBC__)
  GTEST_SKIP() << "malloc interposition needs glibc";
#else
  const Scene scene = MakeTorusScene(/*cells=*/12, /*padding=*/4);
  SparseSurfaceCost cost(scene.mesh, scene.sdf);
  const Eigen::VectorXd u = SampleOnNodes(scene.mesh, 0.3 * scene.h());
  Eigen::VectorXd u2 = 1.1 * u;
  std::vector<Eigen::Vector3d> points = scene.surface.vertices;
  points.push_back(Eigen::Vector3d(5.0, 5.0, 5.0));  // an unmatched outlier
  Eigen::VectorXd gradient;
  std::vector<PointMatch> matches;
  cost.Evaluate(u, points, &gradient, &matches);  // sizes the scratch storage
  cost.Evaluate(u2, points, &gradient, &matches);

  // The interposer sees allocations at all (else the check below would be vacuous).
  allocations = 0;
  counting = true;
  Eigen::VectorXd probe(1000);
  std::vector<int> probe_vector(1000);
  counting = false;
  ASSERT_GE(allocations.load(), 2) << probe.size() << probe_vector.size();

  allocations = 0;
  counting = true;
  const double c1 = cost.Evaluate(u, points, &gradient, &matches);
  const double c2 = cost.Evaluate(u2, points, nullptr, nullptr);
  const double c3 = cost.Evaluate(u, points, &gradient, nullptr);
  counting = false;
  EXPECT_EQ(allocations.load(), 0);
  EXPECT_GT(c1, 0.0);
  EXPECT_GT(c2, 0.0);
  EXPECT_EQ(c1, c3);
#endif
}

}  // namespace
}  // namespace softid::cost
