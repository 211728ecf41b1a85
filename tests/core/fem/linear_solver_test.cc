// LinearSolver: GMRES with the Cholesky preconditioner, and the direct LU fallback for systems
// the preconditioned GMRES cannot finish (indefinite, non-symmetric).
#include "core/fem/linear_solver.h"

#include <dlfcn.h>
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <fstream>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "core/fem/thread_team.h"

// Defined in linear_solver.cc.
extern "C" void GOMP_parallel(void (*)(void*), void*, unsigned, unsigned);

namespace softid::fem {
namespace {

// A 1-D Laplacian-like SPD matrix (3 DOFs per node) plus a skew part and a negative shift, so
// that the result is non-symmetric and indefinite.
LinearSolver::Matrix MakeMatrix(int nodes, double skew, double shift) {
  const int n = 3 * nodes;
  std::vector<Eigen::Triplet<double>> entries;
  for (int i = 0; i < n; ++i) {
    entries.emplace_back(i, i, 2.0 - shift);
    if (i + 3 < n) {
      entries.emplace_back(i, i + 3, -1.0 + skew);
      entries.emplace_back(i + 3, i, -1.0 - skew);
    }
  }
  LinearSolver::Matrix a(n, n);
  a.setFromTriplets(entries.begin(), entries.end());
  return a;
}

Eigen::VectorXd RandomVector(int n) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  Eigen::VectorXd b(n);
  for (int i = 0; i < n; ++i) b[i] = uniform(rng);
  return b;
}

TEST(LinearSolver, GmresSolvesAPreconditionedSystem) {
  const LinearSolver::Matrix a = MakeMatrix(200, 0.05, 0.0);
  const Eigen::VectorXd b = RandomVector(a.rows());
  LinearSolver solver;
  ASSERT_TRUE(solver.Factorize(a, Eigen::Matrix3d::Identity()).ok());
  Eigen::VectorXd x = Eigen::VectorXd::Zero(a.rows());
  LinearSolver::Options options;
  options.relative_tolerance = 1e-10;
  const LinearSolver::Summary summary =
      solver.Solve(a, b, Eigen::Matrix3d::Identity(), options, &x);
  EXPECT_TRUE(summary.converged);
  EXPECT_LT((a * x - b).norm(), 1e-9 * b.norm());
}

// A stiff non-symmetric change on a few nodes (a contact's stick and slip) that the factor does
// not know costs GMRES many iterations; the correction with the current matrix's block on those
// nodes brings them back near what a fresh factor needs, and the solution is as accurate.
TEST(LinearSolver, CorrectionOnChangedNodesRestoresTheIterationsOfAFreshFactor) {
  const int num_nodes = 400;
  const LinearSolver::Matrix reference = MakeMatrix(num_nodes, 0.0, 0.0);
  std::vector<int> changed;
  std::vector<Eigen::Triplet<double>> entries;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  for (int node = 180; node < 200; ++node) {
    changed.push_back(node);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        entries.emplace_back(3 * node + i, 3 * node + j,
                             (i == j ? 400.0 : 0.0) + 100.0 * uniform(rng));
  }
  LinearSolver::Matrix change(reference.rows(), reference.cols());
  change.setFromTriplets(entries.begin(), entries.end());
  const LinearSolver::Matrix a = reference + change;
  const Eigen::VectorXd b = RandomVector(a.rows());
  LinearSolver::Options options;
  options.relative_tolerance = 1e-8;
  options.max_iterations = 2000;
  const auto iterations = [&](LinearSolver& solver, bool corrected) {
    if (corrected) {
      EXPECT_TRUE(solver.SetCorrection(changed, SubdomainCorrection::Rows(a, changed, false)));
      EXPECT_EQ(solver.CorrectionNodes(), 20);
    }
    Eigen::VectorXd x = Eigen::VectorXd::Zero(a.rows());
    const LinearSolver::Summary summary =
        solver.Solve(a, b, Eigen::Matrix3d::Identity(), options, &x);
    EXPECT_TRUE(summary.converged);
    EXPECT_LT((a * x - b).norm(), 1e-7 * b.norm());
    solver.ClearCorrection();
    return summary.iterations;
  };
  LinearSolver stale;
  ASSERT_TRUE(stale.Factorize(reference, Eigen::Matrix3d::Identity()).ok());
  LinearSolver fresh;
  ASSERT_TRUE(fresh.Factorize(a, Eigen::Matrix3d::Identity()).ok());
  const int uncorrected = iterations(stale, false);
  const int corrected = iterations(stale, true);
  const int fresh_iterations = iterations(fresh, false);
  EXPECT_GT(uncorrected, 3 * corrected);
  EXPECT_LE(corrected, fresh_iterations + 3);
}

// At tolerances >= 1e-8 GMRES reports its recurrence's residual without a final product; it must
// be the true one: over a stale preconditioner (many iterations, a restart), for both operators
// and from a zero and a non-zero initial guess, the reported and the true residual agree.
TEST(LinearSolver, ReportedResidualIsTheTrueResidual) {
  const LinearSolver::Matrix reference = MakeMatrix(300, 0.0, 0.0);
  const LinearSolver::Matrix a = MakeMatrix(300, 0.1, 0.0);
  const Eigen::VectorXd b = RandomVector(a.rows());
  LinearSolver solver;
  ASSERT_TRUE(solver.Factorize(reference, Eigen::Matrix3d::Identity()).ok());
  LinearSolver::Options options;
  options.relative_tolerance = 1e-6;
  options.restart = 6;
  for (const auto op : {LinearSolver::Operator::kMatrix, LinearSolver::Operator::kTransposed}) {
    for (const double guess : {0.0, 0.5}) {
      Eigen::VectorXd x = Eigen::VectorXd::Constant(a.rows(), guess);
      const LinearSolver::Summary summary =
          solver.Solve(a, b, Eigen::Matrix3d::Identity(), options, &x, op);
      ASSERT_TRUE(summary.converged);
      EXPECT_GT(summary.iterations, options.restart);  // the stale factor needed a restart
      const Eigen::VectorXd residual = op == LinearSolver::Operator::kMatrix
                                           ? Eigen::VectorXd(b - a * x)
                                           : Eigen::VectorXd(b - a.transpose() * x);
      const double true_relative = residual.norm() / b.norm();
      EXPECT_LE(true_relative, options.relative_tolerance);
      EXPECT_NEAR(summary.relative_residual, true_relative, 1e-3 * true_relative)
          << "guess " << guess;
    }
  }
}

// A symmetric matrix may be factored as it is (Symmetry::kSymmetric, no (A + A^T) / 2 formed):
// the factor is the same, so the preconditioner gives bitwise the same estimate, which solves
// the SPD system to the single-precision factor's accuracy.
TEST(LinearSolver, SymmetricMatrixFactoredAsItIs) {
  const LinearSolver::Matrix a = MakeMatrix(300, 0.0, -0.5);
  const Eigen::VectorXd b = RandomVector(a.rows());
  LinearSolver general, symmetric;
  ASSERT_TRUE(general.Factorize(a, Eigen::Matrix3d::Identity()).ok());
  ASSERT_TRUE(
      symmetric.Factorize(a, Eigen::Matrix3d::Identity(), LinearSolver::Symmetry::kSymmetric).ok());
  Eigen::VectorXd x_general, x_symmetric;
  general.Precondition(b, Eigen::Matrix3d::Identity(), &x_general);
  symmetric.Precondition(b, Eigen::Matrix3d::Identity(), &x_symmetric);
  EXPECT_EQ(x_general, x_symmetric);
  EXPECT_LT((a * x_symmetric - b).norm(), 1e-4 * b.norm());
}

int ThreadsOfThisProcess() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind("Threads:", 0) == 0) return std::stoi(line.substr(8));
  }
  return -1;
}

TEST(LinearSolver, FactorisationRunsOnTheCallingThread) {
  // CHOLMOD's OpenMP regions must run serialised (see GOMP_parallel in linear_solver.cc): the
  // process-wide definition is the one the dynamic linker binds, and factorising a matrix large
  // enough for CHOLMOD's parallel loops (> 128 unknowns) starts no thread.
  EXPECT_EQ(dlsym(RTLD_DEFAULT, "GOMP_parallel"), reinterpret_cast<void*>(&GOMP_parallel));
  const int before = ThreadsOfThisProcess();
  ASSERT_GT(before, 0);
  const LinearSolver::Matrix a = MakeMatrix(2000, 0.0, 0.0);
  LinearSolver solver;
  ASSERT_TRUE(solver.Factorize(a, Eigen::Matrix3d::Identity()).ok());
  EXPECT_EQ(ThreadsOfThisProcess(), before);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(a.rows());
  const Eigen::VectorXd b = RandomVector(a.rows());
  EXPECT_TRUE(
      solver.Solve(a, b, Eigen::Matrix3d::Identity(), LinearSolver::Options(), &x).converged);
}

// A 3-D grid Laplacian (3 unknowns per node, plus a skew part): its nested-dissection elimination
// tree branches, as the FE systems' do, so a team has whole subtrees to split.
LinearSolver::Matrix GridMatrix(int side, double skew) {
  const auto node = [side](int i, int j, int k) { return (i * side + j) * side + k; };
  std::vector<Eigen::Triplet<double>> entries;
  for (int i = 0; i < side; ++i) {
    for (int j = 0; j < side; ++j) {
      for (int k = 0; k < side; ++k) {
        const int a = node(i, j, k);
        for (int d = 0; d < 3; ++d) entries.emplace_back(3 * a + d, 3 * a + d, 6.5);
        const int neighbours[3] = {i + 1 < side ? node(i + 1, j, k) : -1,
                                   j + 1 < side ? node(i, j + 1, k) : -1,
                                   k + 1 < side ? node(i, j, k + 1) : -1};
        for (int b : neighbours) {
          if (b < 0) continue;
          for (int d = 0; d < 3; ++d) {
            entries.emplace_back(3 * a + d, 3 * b + d, -1.0 + skew);
            entries.emplace_back(3 * b + d, 3 * a + d, -1.0 - skew);
          }
        }
      }
    }
  }
  const int n = 3 * side * side * side;
  LinearSolver::Matrix a(n, n);
  a.setFromTriplets(entries.begin(), entries.end());
  return a;
}

// On a team of two the triangular solves split the elimination tree and the products split the
// columns: the preconditioner agrees with one thread's to single precision, the GMRES solutions
// (plain and transposed) to the tolerance, and repeated solves are bitwise equal.
TEST(LinearSolver, TeamOfTwoSolvesAsOneThreadDoes) {
  const LinearSolver::Matrix a = GridMatrix(14, 0.1);
  const Eigen::VectorXd b = RandomVector(a.rows());
  const Eigen::Matrix3d rotation =
      Eigen::AngleAxisd(0.3, Eigen::Vector3d(1.0, 2.0, 3.0).normalized()).toRotationMatrix();
  ThreadTeam team(2);
  LinearSolver single, parallel;
  parallel.SetThreadTeam(&team);
  ASSERT_TRUE(single.Factorize(a, rotation).ok());
  ASSERT_TRUE(parallel.Factorize(a, rotation).ok());
  EXPECT_EQ(single.ParallelShare(), 0.0);
  EXPECT_GT(parallel.ParallelShare(), 0.6);  // most of the factor is solved by the members

  Eigen::VectorXd z_single, z_parallel, z_again;
  single.Precondition(b, rotation, &z_single);
  parallel.Precondition(b, rotation, &z_parallel);
  parallel.Precondition(b, rotation, &z_again);
  EXPECT_LT((z_parallel - z_single).norm(), 1e-5 * z_single.norm());
  EXPECT_TRUE(z_again == z_parallel);

  LinearSolver::Options options;
  options.relative_tolerance = 1e-11;
  for (auto op : {LinearSolver::Operator::kMatrix, LinearSolver::Operator::kTransposed}) {
    Eigen::VectorXd x_single = Eigen::VectorXd::Zero(a.rows());
    Eigen::VectorXd x_parallel = x_single, x_repeat = x_single;
    ASSERT_TRUE(single.Solve(a, b, rotation, options, &x_single, op).converged);
    ASSERT_TRUE(parallel.Solve(a, b, rotation, options, &x_parallel, op).converged);
    ASSERT_TRUE(parallel.Solve(a, b, rotation, options, &x_repeat, op).converged);
    const Eigen::VectorXd ax = op == LinearSolver::Operator::kTransposed
                                   ? Eigen::VectorXd(a.transpose() * x_parallel)
                                   : Eigen::VectorXd(a * x_parallel);
    EXPECT_LT((ax - b).norm(), 1e-10 * b.norm());
    EXPECT_LT((x_parallel - x_single).norm(), 1e-9 * x_single.norm());
    EXPECT_TRUE(x_repeat == x_parallel);
  }
  // A team set after the factorisation re-plans the factor's solves.
  single.SetThreadTeam(&team);
  EXPECT_GT(single.ParallelShare(), 0.6);
  single.Precondition(b, rotation, &z_single);
  EXPECT_TRUE(z_single == z_parallel);
}

// A hexahedral grid's stiffness pattern: each node coupled to its 26 neighbours, all 3 x 3 unknowns
// (SPD: diagonally dominant).
LinearSolver::Matrix HexGridMatrix(int side) {
  const auto node = [side](int i, int j, int k) { return (i * side + j) * side + k; };
  std::vector<Eigen::Triplet<double>> entries;
  for (int i = 0; i < side; ++i) {
    for (int j = 0; j < side; ++j) {
      for (int k = 0; k < side; ++k) {
        for (int di = -1; di <= 1; ++di) {
          for (int dj = -1; dj <= 1; ++dj) {
            for (int dk = -1; dk <= 1; ++dk) {
              const int ni = i + di, nj = j + dj, nk = k + dk;
              if (ni < 0 || nj < 0 || nk < 0 || ni >= side || nj >= side || nk >= side) continue;
              const bool self = di == 0 && dj == 0 && dk == 0;
              for (int d = 0; d < 3; ++d) {
                for (int e = 0; e < 3; ++e) {
                  const double value = self ? (d == e ? 100.0 : 0.5) : (d == e ? -1.0 : -0.1);
                  entries.emplace_back(3 * node(i, j, k) + d, 3 * node(ni, nj, nk) + e, value);
                }
              }
            }
          }
        }
      }
    }
  }
  const int n = 3 * side * side * side;
  LinearSolver::Matrix a(n, n);
  a.setFromTriplets(entries.begin(), entries.end());
  return a;
}

// Solvers factorising at the same time on several threads (a fit's concurrent starts) get the
// factor one thread alone gets: CHOLMOD's analysis of a hexahedral grid's matrix tries METIS, whose
// random-number state is global, so analyses running at once drew from each other's sequence and
// ordered the same matrix differently (linear_solver.cc serialises them).
TEST(LinearSolver, ConcurrentFactorisationsEqualASequentialOne) {
  const LinearSolver::Matrix a = HexGridMatrix(14);
  const Eigen::VectorXd b = RandomVector(a.rows());
  const Eigen::Matrix3d identity = Eigen::Matrix3d::Identity();
  LinearSolver alone;
  ASSERT_TRUE(alone.Factorize(a, identity, LinearSolver::Symmetry::kSymmetric).ok());
  Eigen::VectorXd z_alone;
  alone.Precondition(b, identity, &z_alone);

  constexpr int kThreads = 2, kRounds = 4;
  std::vector<std::vector<Eigen::VectorXd>> z(kThreads, std::vector<Eigen::VectorXd>(kRounds));
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      for (int round = 0; round < kRounds; ++round) {
        LinearSolver solver;
        if (solver.Factorize(a, identity, LinearSolver::Symmetry::kSymmetric).ok())
          solver.Precondition(b, identity, &z[t][round]);
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  for (int t = 0; t < kThreads; ++t) {
    for (int round = 0; round < kRounds; ++round) {
      EXPECT_TRUE(z[t][round] == z_alone) << "thread " << t << ", round " << round;
    }
  }
}

// The factor is kept in reduced precision (single, and half below the diagonal blocks where the
// CPU converts halves, each column scaled to its largest entry): whatever the system's units,
// from 1e-9 to 1e12 (a half alone spans ~6e-8 to 65504), the preconditioner alone still solves a
// freshly factored SPD system to 1e-3 relative, on one thread and on a team.
TEST(LinearSolver, ReducedPrecisionFactorSolvesFreshSystemsAtAnyScale) {
  const LinearSolver::Matrix unit = GridMatrix(12, 0.0);
  const Eigen::VectorXd b = RandomVector(unit.rows());
  ThreadTeam team(2);
  for (const double scale : {1e-9, 1.0, 1e12}) {
    const LinearSolver::Matrix a = scale * unit;
    for (const bool on_team : {false, true}) {
      LinearSolver solver;
      if (on_team) solver.SetThreadTeam(&team);
      ASSERT_TRUE(solver.Factorize(a, Eigen::Matrix3d::Identity()).ok());
      Eigen::VectorXd x;
      solver.Precondition(b, Eigen::Matrix3d::Identity(), &x);
      ASSERT_TRUE(x.allFinite()) << "scale " << scale;
      EXPECT_LT((a * x - b).norm(), 1e-3 * b.norm()) << "scale " << scale << " team " << on_team;
    }
  }
}

// A factorisation in the background leaves the current factor in use until FinishFactorize, then
// gives exactly the factor a synchronous one gives; a failed one leaves the previous factor.
TEST(LinearSolver, BackgroundFactorisationIsAdoptedOnlyWhenFinished) {
  const LinearSolver::Matrix first = GridMatrix(12, 0.0);
  LinearSolver::Matrix second = first;
  second.diagonal() *= 2.0;
  const Eigen::VectorXd b = RandomVector(first.rows());
  const Eigen::Matrix3d identity = Eigen::Matrix3d::Identity();
  ThreadTeam team(2);
  LinearSolver background, reference_first, reference_second;
  for (LinearSolver* solver : {&background, &reference_first, &reference_second})
    solver->SetThreadTeam(&team);
  ASSERT_TRUE(background.Factorize(first, identity).ok());
  ASSERT_TRUE(reference_first.Factorize(first, identity).ok());
  ASSERT_TRUE(reference_second.Factorize(second, identity).ok());
  Eigen::VectorXd z, z_first, z_second;
  reference_first.Precondition(b, identity, &z_first);
  reference_second.Precondition(b, identity, &z_second);
  ASSERT_FALSE(z_first == z_second);

  ASSERT_TRUE(background.StartFactorize(second, identity).ok());
  EXPECT_TRUE(background.FactorizationPending());
  background.Precondition(b, identity, &z);  // the team runs on this thread meanwhile
  EXPECT_TRUE(z == z_first);
  EXPECT_TRUE(background.FinishFactorize());
  EXPECT_FALSE(background.FactorizationPending());
  EXPECT_EQ(background.num_factorizations(), 2);
  background.Precondition(b, identity, &z);
  EXPECT_TRUE(z == z_second);

  // Not positive definite even with the largest shift: the previous factor stays.
  LinearSolver::Matrix broken = second;
  broken.coeffRef(0, 0) = -1e6;
  ASSERT_TRUE(background.StartFactorize(broken, identity).ok());
  EXPECT_FALSE(background.FinishFactorize());
  background.Precondition(b, identity, &z);
  EXPECT_TRUE(z == z_second);

  // Without a team it is adopted at the same point: FinishFactorize computes it.
  LinearSolver alone;
  ASSERT_TRUE(alone.Factorize(first, identity).ok());
  ASSERT_TRUE(alone.StartFactorize(second, identity).ok());
  EXPECT_TRUE(alone.FactorizationPending());
  alone.Precondition(b, identity, &z);
  EXPECT_LT((z - z_first).norm(), 1e-6 * z_first.norm());
  EXPECT_TRUE(alone.FinishFactorize());
  EXPECT_FALSE(alone.FactorizationPending());
  alone.Precondition(b, identity, &z);
  EXPECT_LT((z - z_second).norm(), 1e-6 * z_second.norm());
}

// A background factorisation is adopted when due: at the max_calls-th call when the solver did no
// work meanwhile, at the first call once its solves have done about the factorisation's work
// (work model, not time), and never before it is adopted gives the new factor.
TEST(LinearSolver, BackgroundFactorisationIsAdoptedWhenDue) {
  const LinearSolver::Matrix first = GridMatrix(12, 0.0);
  LinearSolver::Matrix second = first;
  second.diagonal() *= 2.0;
  const Eigen::VectorXd b = RandomVector(first.rows());
  const Eigen::Matrix3d identity = Eigen::Matrix3d::Identity();
  ThreadTeam team(2);
  LinearSolver solver, reference_second;
  solver.SetThreadTeam(&team);
  reference_second.SetThreadTeam(&team);
  ASSERT_TRUE(solver.Factorize(first, identity).ok());
  ASSERT_TRUE(reference_second.Factorize(second, identity).ok());
  Eigen::VectorXd z_second;
  reference_second.Precondition(b, identity, &z_second);

  // No work meanwhile: adopted at the third call.
  ASSERT_TRUE(solver.StartFactorize(second, identity).ok());
  EXPECT_FALSE(solver.FinishFactorizeWhenDue(3));
  EXPECT_FALSE(solver.FinishFactorizeWhenDue(3));
  EXPECT_TRUE(solver.FactorizationPending());
  EXPECT_TRUE(solver.FinishFactorizeWhenDue(3));
  EXPECT_FALSE(solver.FactorizationPending());
  Eigen::VectorXd z;
  solver.Precondition(b, identity, &z);
  EXPECT_TRUE(z == z_second);

  // Solves meanwhile worth more than the factorisation: adopted at the first call.
  ASSERT_TRUE(solver.StartFactorize(first, identity).ok());
  LinearSolver::Options options;
  options.relative_tolerance = 1e-30;  // out of reach: every solve runs its iterations
  options.max_iterations = 200;
  Eigen::VectorXd x = Eigen::VectorXd::Zero(b.size());
  solver.Solve(second, b, identity, options, &x);
  EXPECT_TRUE(solver.FinishFactorizeWhenDue(1000));
  EXPECT_EQ(solver.num_factorizations(), 3);
}

// A general matrix is factored as its symmetric part (a + a^T) / 2, formed in place when the
// pattern is structurally symmetric (as the assembly's is) and by a transposed copy otherwise: the
// same factor, bitwise, as factoring that part given as symmetric; again after the values change
// on the same pattern (the cached transpose map), and for a pattern with one-sided entries.
TEST(LinearSolver, GeneralMatrixIsFactoredAsItsSymmetricPart) {
  const Eigen::Matrix3d identity = Eigen::Matrix3d::Identity();
  const auto expect_as_symmetric_part = [&](LinearSolver& solver, const LinearSolver::Matrix& a) {
    const LinearSolver::Matrix part = 0.5 * (a + LinearSolver::Matrix(a.transpose()));
    LinearSolver reference;
    ASSERT_TRUE(reference.Factorize(part, identity, LinearSolver::Symmetry::kSymmetric).ok());
    ASSERT_TRUE(solver.Factorize(a, identity).ok());
    const Eigen::VectorXd b = RandomVector(a.rows());
    Eigen::VectorXd x, x_reference;
    solver.Precondition(b, identity, &x);
    reference.Precondition(b, identity, &x_reference);
    EXPECT_TRUE(x == x_reference);
  };
  LinearSolver solver;
  expect_as_symmetric_part(solver, GridMatrix(6, 0.3));
  expect_as_symmetric_part(solver, GridMatrix(6, -0.2));  // same pattern, new values
  LinearSolver::Matrix one_sided = GridMatrix(6, 0.3);
  one_sided.coeffRef(0, 50) += 0.1;  // no (50, 0) entry
  one_sided.makeCompressed();
  expect_as_symmetric_part(solver, one_sided);
}

TEST(LinearSolver, DirectSolveHandlesAnIndefiniteNonSymmetricTransposedSystem) {
  // Shifted by more than the smallest eigenvalue of the Laplacian: indefinite.
  const LinearSolver::Matrix a = MakeMatrix(200, 0.05, 0.5);
  const Eigen::VectorXd b = RandomVector(a.rows());
  LinearSolver::Options options;
  options.relative_tolerance = 1e-10;
  for (auto op : {LinearSolver::Operator::kMatrix, LinearSolver::Operator::kTransposed}) {
    Eigen::VectorXd x;
    const LinearSolver::Summary summary = LinearSolver::SolveDirect(a, b, options, &x, op);
    ASSERT_TRUE(summary.converged) << summary.relative_residual;
    const Eigen::VectorXd ax = op == LinearSolver::Operator::kTransposed
                                   ? Eigen::VectorXd(a.transpose() * x)
                                   : Eigen::VectorXd(a * x);
    EXPECT_LT((ax - b).norm(), 1e-9 * b.norm());
    EXPECT_NEAR(summary.relative_residual, (ax - b).norm() / b.norm(), 1e-12);
  }
}

TEST(LinearSolver, DirectSolveReportsASingularSystem) {
  LinearSolver::Matrix a(6, 6);  // all zero
  a.makeCompressed();
  const Eigen::VectorXd b = Eigen::VectorXd::Ones(6);
  Eigen::VectorXd x;
  EXPECT_FALSE(LinearSolver::SolveDirect(a, b, LinearSolver::Options(), &x).converged);
}

}  // namespace
}  // namespace softid::fem
