#include "core/fem/elastic_modes.h"

#include <Spectra/MatOp/SparseSymMatProd.h>
#include <Spectra/SymGEigsShiftSolver.h>

#include <Eigen/CholmodSupport>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace softid::fem {
namespace {

using SparseMatrix = Eigen::SparseMatrix<double>;

// K and M restricted to the free nodes' degrees of freedom (a fixed node's identity rows would
// otherwise add spurious modes at 1 / m).
struct FreeSystem {
  SparseMatrix stiffness, mass;
};

FreeSystem RestrictToFreeNodes(Simulator& simulator) {
  const SparseMatrix k = simulator.RestStiffnessMatrix();
  const int nodes = simulator.hex_mesh().NumNodes();
  std::vector<int> free_index(3 * nodes, -1);
  int n = 0;
  for (int i = 0; i < nodes; ++i) {
    if (simulator.is_fixed(i)) continue;
    for (int c = 0; c < 3; ++c) free_index[3 * i + c] = n++;
  }
  std::vector<Eigen::Triplet<double>> entries;
  entries.reserve(k.nonZeros());
  for (int col = 0; col < k.outerSize(); ++col) {
    if (free_index[col] < 0) continue;
    for (SparseMatrix::InnerIterator it(k, col); it; ++it) {
      if (free_index[it.row()] >= 0)
        entries.emplace_back(free_index[it.row()], free_index[col], it.value());
    }
  }
  FreeSystem system;
  system.stiffness.resize(n, n);
  system.stiffness.setFromTriplets(entries.begin(), entries.end());
  system.mass.resize(n, n);
  system.mass.reserve(Eigen::VectorXi::Constant(n, 1));
  for (int i = 0; i < nodes; ++i) {
    for (int c = 0; c < 3; ++c) {
      if (free_index[3 * i + c] >= 0)
        system.mass.insert(free_index[3 * i + c], free_index[3 * i + c]) =
            simulator.lumped_mass()[i];
    }
  }
  system.mass.makeCompressed();
  return system;
}

// y = (K - sigma M)^-1 x for Spectra's shift-invert mode, by a supernodal Cholesky factor
// (CHOLMOD): K - sigma M is positive definite for sigma < 0. Spectra's own SymShiftInvert takes a
// sparse LU, which needed 5.9 GB at 48 cells on the thrown block.
class ShiftedCholeskySolve {
 public:
  using Scalar = double;
  ShiftedCholeskySolve(const SparseMatrix& stiffness, const SparseMatrix& mass)
      : stiffness_(stiffness), mass_(mass) {}
  Eigen::Index rows() const { return stiffness_.rows(); }
  Eigen::Index cols() const { return stiffness_.cols(); }
  void set_shift(double sigma) {
    const SparseMatrix shifted = stiffness_ - sigma * mass_;
    factor_.compute(shifted);
    if (factor_.info() != Eigen::Success)
      throw std::invalid_argument("elastic modes: K - sigma M is not positive definite");
  }
  void perform_op(const double* x, double* y) const {
    Eigen::Map<Eigen::VectorXd>(y, rows()) =
        factor_.solve(Eigen::Map<const Eigen::VectorXd>(x, rows()));
  }

 private:
  const SparseMatrix& stiffness_;
  const SparseMatrix& mass_;
  Eigen::CholmodSupernodalLLT<SparseMatrix, Eigen::Lower> factor_;
};

double FrequencyHz(double eigenvalue) {
  return std::sqrt(std::max(eigenvalue, 0.0)) / (2.0 * M_PI);
}

}  // namespace

Result<ElasticModes> ComputeElasticModes(Simulator& simulator, const ElasticModesOptions& options) {
  if (options.count < 1)
    return Status::InvalidArgument("count = " + std::to_string(options.count) + ": must be >= 1");
  FreeSystem system = RestrictToFreeNodes(simulator);
  const int n = static_cast<int>(system.stiffness.rows());
  ElasticModes modes;
  modes.degrees_of_freedom = n;
  modes.rigid_modes = simulator.num_fixed_nodes() > 0 ? 0 : 6;
  const int wanted = options.count + modes.rigid_modes;
  if (wanted >= n)
    return Status::InvalidArgument("count = " + std::to_string(options.count) +
                                   ": the grid has only " + std::to_string(n) +
                                   " degrees of freedom");
  // Shift-invert about a small negative shift: K - sigma M is positive definite even with the
  // rigid modes' zero eigenvalues, and the modes nearest zero converge first. The shift is a
  // small fraction of the median ratio K_ii / M_ii, the order of a single cell's w^2 (not the
  // mean: a sliver of a cut cell has a tiny mass and an outsized ratio).
  Eigen::VectorXd ratio = system.stiffness.diagonal().array() / system.mass.diagonal().array();
  std::nth_element(ratio.data(), ratio.data() + n / 2, ratio.data() + n);
  const double shift = -1e-6 * ratio[n / 2];
  using MassProduct = Spectra::SparseSymMatProd<double>;
  ShiftedCholeskySolve op(system.stiffness, system.mass);
  MassProduct mass_product(system.mass);
  const int subspace = std::min(n, std::max(2 * wanted + 1, 30));
  Spectra::SymGEigsShiftSolver<ShiftedCholeskySolve, MassProduct, Spectra::GEigsMode::ShiftInvert>
      solver(op, mass_product, wanted, subspace, shift);
  try {
    solver.init();
    solver.compute(Spectra::SortRule::LargestMagn, 1000, 1e-10);
  } catch (const std::invalid_argument& e) {
    return Status::Internal(e.what());
  }
  if (solver.info() != Spectra::CompInfo::Successful)
    return Status::Internal("elastic modes: the eigensolver did not converge (" +
                            std::to_string(wanted) + " modes, " + std::to_string(n) +
                            " degrees of freedom)");
  const Eigen::VectorXd found = solver.eigenvalues();
  std::vector<double> eigenvalues(found.data(), found.data() + found.size());
  std::sort(eigenvalues.begin(), eigenvalues.end());
  for (int i = 0; i < modes.rigid_modes; ++i)
    modes.rigid_frequency_hz =
        std::max(modes.rigid_frequency_hz, FrequencyHz(std::abs(eigenvalues[i])));
  for (int i = modes.rigid_modes; i < wanted; ++i)
    modes.frequencies_hz.push_back(FrequencyHz(eigenvalues[i]));
  return modes;
}

}  // namespace softid::fem
