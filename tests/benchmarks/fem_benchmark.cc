// Micro-benchmarks of one simulation step's parts, on the torus-drop scene at ~3,100 active cells
// (26 cells along its longest side) during its impact, where the time goes: the step matrix's
// assembly, its factorisation, a preconditioner application (two triangular solves) and a product
// with the matrix. SOFTID_THREADS=2 runs them on a team of two threads (default one).
#include <benchmark/benchmark.h>

#include <chrono>
#include <cstdlib>
#include <memory>

#include "core/fem/linear_solver.h"
#include "core/fem/simulator.h"
#include "core/fem/thread_team.h"
#include "core/scenes/scene.h"

namespace softid {
namespace {

int Threads() {
  const char* t = std::getenv("SOFTID_THREADS");
  return t != nullptr ? std::atoi(t) : 1;
}

struct ImpactFixture {
  std::unique_ptr<fem::Simulator> sim;
  Eigen::VectorXd u_next;
  fem::LinearSolver::Matrix matrix;
  Eigen::VectorXd rhs;

  static ImpactFixture& Get() {
    static ImpactFixture fixture = [] {
      ImpactFixture f;
      scenes::Scene scene = scenes::MakeBuiltinScene("torus-drop").value();
      fem::SimulationOptions options;
      options.cells_along_longest_side = 26;
      options.time_step = 1.0 / 240.0;
      options.threads = Threads();
      f.sim = std::make_unique<fem::Simulator>(scene.mesh, scene.parameters, options);
      for (int k = 0; k < 46; ++k) f.sim->Step();  // into the impact
      const fem::SimulationState before = f.sim->state();
      f.sim->Step();
      f.u_next = f.sim->state().u;
      f.sim->SetState(before);
      Eigen::SparseMatrix<double> jacobian;
      f.sim->EvaluateStepResidual(f.u_next, &f.rhs, &jacobian);
      f.matrix = jacobian;
      f.rhs = Eigen::VectorXd::Random(f.rhs.size());
      return f;
    }();
    return fixture;
  }
};

void BM_StepJacobianAssembly(benchmark::State& state) {
  ImpactFixture& f = ImpactFixture::Get();
  Eigen::VectorXd residual;
  Eigen::SparseMatrix<double> jacobian;
  for (auto _ : state) {
    f.sim->EvaluateStepResidual(f.u_next, &residual, &jacobian);
    benchmark::DoNotOptimize(jacobian.valuePtr());
  }
  state.counters["elements"] = f.sim->hex_mesh().NumElements();
}
BENCHMARK(BM_StepJacobianAssembly)->Unit(benchmark::kMillisecond);

void BM_Factorize(benchmark::State& state) {
  ImpactFixture& f = ImpactFixture::Get();
  fem::LinearSolver solver;
  for (auto _ : state) {
    benchmark::DoNotOptimize(solver.Factorize(f.matrix, Eigen::Matrix3d::Identity()).ok());
  }
  state.counters["unknowns"] = static_cast<double>(f.matrix.rows());
}
BENCHMARK(BM_Factorize)->Unit(benchmark::kMillisecond);

// A solver on a team of Threads() with the factor of `matrix`.
struct FactoredSolver {
  fem::ThreadTeam team{Threads()};
  fem::LinearSolver solver;
  FactoredSolver(const fem::LinearSolver::Matrix& matrix, benchmark::State& state) {
    solver.SetThreadTeam(&team);
    if (!solver.Factorize(matrix, Eigen::Matrix3d::Identity()).ok()) state.SkipWithError("factor");
  }
};

void BM_Precondition(benchmark::State& state) {
  ImpactFixture& f = ImpactFixture::Get();
  FactoredSolver factored(f.matrix, state);
  fem::LinearSolver& solver = factored.solver;
  Eigen::VectorXd x;
  for (auto _ : state) {
    solver.Precondition(f.rhs, Eigen::Matrix3d::Identity(), &x);
    benchmark::DoNotOptimize(x.data());
  }
}
BENCHMARK(BM_Precondition)->Unit(benchmark::kMicrosecond);

// Ten GMRES iterations (tolerance out of reach) preconditioned by the factor of a nearby matrix.
void BM_TenGmresIterations(benchmark::State& state) {
  ImpactFixture& f = ImpactFixture::Get();
  fem::LinearSolver::Matrix nearby = f.matrix;
  nearby.diagonal() *= 1.5;
  FactoredSolver factored(nearby, state);
  fem::LinearSolver& solver = factored.solver;
  fem::LinearSolver::Options options;
  options.relative_tolerance = 1e-30;
  options.max_iterations = 10;
  Eigen::VectorXd x;
  for (auto _ : state) {
    x.setZero(f.rhs.size());
    solver.Solve(f.matrix, f.rhs, Eigen::Matrix3d::Identity(), options, &x);
    benchmark::DoNotOptimize(x.data());
  }
}
BENCHMARK(BM_TenGmresIterations)->Unit(benchmark::kMillisecond);

void BM_MatrixProduct(benchmark::State& state) {
  ImpactFixture& f = ImpactFixture::Get();
  Eigen::VectorXd y(f.rhs.size());
  for (auto _ : state) {
    y.noalias() = f.matrix * f.rhs;
    benchmark::DoNotOptimize(y.data());
  }
  state.counters["nonzeros"] = static_cast<double>(f.matrix.nonZeros());
}
BENCHMARK(BM_MatrixProduct)->Unit(benchmark::kMicrosecond);

// One empty parallel region on a team of two after `serial` microseconds of work on the caller
// alone (a step's bookkeeping between GMRES's regions): the cost of waking the worker. Arg 1:
// the team's spin before a worker sleeps [us] (0: sleep at once). Dev VM, quiet: ~70-90 us
// sleeping, ~3-5 us spinning.
void BM_TeamRegionAfterSerialWork(benchmark::State& state) {
  fem::ThreadTeam team(2, std::chrono::microseconds(state.range(1)));
  const auto serial = std::chrono::microseconds(state.range(0));
  long sum = 0;
  for (auto _ : state) {
    state.PauseTiming();
    const auto until = std::chrono::steady_clock::now() + serial;
    while (std::chrono::steady_clock::now() < until) {
    }
    state.ResumeTiming();
    team.Run([&](int member) { benchmark::DoNotOptimize(sum += member); });
  }
}
BENCHMARK(BM_TeamRegionAfterSerialWork)
    ->ArgsProduct({{20, 200}, {0, fem::ThreadTeam::kDefaultSpin.count()}})
    ->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace softid

BENCHMARK_MAIN();
