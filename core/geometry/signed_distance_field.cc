#include "core/geometry/signed_distance_field.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <string>
#include <thread>

#include "core/geometry/cut_cell_weights.h"
#include "core/geometry/mesh_distance.h"
#include "core/geometry/winding_number.h"

namespace softid::geometry {
namespace {

constexpr long long kMaxNodes = 1LL << 27;
// Extents within this fraction of a cell above a whole number of cells count as that number [-].
constexpr double kWholeCellTolerance = 1e-3;
constexpr int kNodesPerTask = 512;
// A cut cell's lattice costs (n + 1)^3 distance queries; a few cells per task keep the counter
// cold.
constexpr int kCutCellsPerTask = 4;
constexpr double kCoarseDecisionMargin = 0.1;

std::string Field(const char* name) {
  return std::string("SignedDistanceOptions.") + name;
}

// Cell size h [m]: options.cell_size, or the longest side split into cells_along_longest_side.
Result<double> ChooseCellSize(const Eigen::Vector3d& extent, const SignedDistanceOptions& options) {
  double h = options.cell_size;
  if (h <= 0.0) {
    h = extent.maxCoeff() / options.cells_along_longest_side;
    if (!(h > 0.0)) {
      return Status::InvalidArgument(
          "mesh: bounds have zero extent; set SignedDistanceOptions.cell_size");
    }
  }
  return h;
}

// A grid of cell size h centred on the mesh bounds (extent = bounds.sizes()), padded on every
// side; InvalidArgument if it would have more than kMaxNodes nodes.
Status LayOutGrid(const Eigen::AlignedBox3d& bounds, const Eigen::Vector3d& extent, double h,
                  const SignedDistanceOptions& options, RegularGrid* grid) {
  long long num_nodes = 1;
  for (int a = 0; a < 3; ++a) {
    // A tolerance keeps whole multiples of h (extent = 9 h) from gaining a cell by rounding, which
    // would put both faces mid-cell: mesh files hold single-precision coordinates (assimp reads
    // floats), so a box 0.06 m deep at h = 0.1 m / 15 measures 9.0000004 h. A body that overhangs
    // a node plane by less than kWholeCellTolerance h loses that sliver, far less than the cut
    // cells min_cell_volume_fraction drops.
    const double aligned_padding = std::isnan(options.node_plane[a]) ? 0.0 : 2.0;
    const double cells = std::max(0.0, std::ceil(extent[a] / h - kWholeCellTolerance)) +
                         2.0 * options.padding_cells + aligned_padding;
    if (cells + 1 > static_cast<double>(kMaxNodes)) {
      num_nodes = kMaxNodes + 1;
      break;
    }
    grid->num_cells[a] = static_cast<int>(cells);
    num_nodes *= grid->num_cells[a] + 1;
  }
  if (num_nodes > kMaxNodes) {
    return Status::InvalidArgument("SignedDistanceOptions: cell_size h = " + std::to_string(h) +
                                   " m gives more than 2^27 grid nodes for mesh extent " +
                                   std::to_string(extent.maxCoeff()) + " m");
  }
  grid->cell_size = h;
  grid->origin = bounds.center() - 0.5 * h * grid->num_cells.cast<double>();
  for (int a = 0; a < 3; ++a) {
    if (std::isnan(options.node_plane[a])) continue;
    // Up by less than a cell from the centred place; the extra cell on each side keeps the padding.
    const double below = grid->origin[a];
    grid->origin[a] +=
        options.node_plane[a] - below - h * std::floor((options.node_plane[a] - below) / h);
  }
  return Status::Ok();
}

// Calls task(begin, end) on consecutive ranges of [0, count) of at most chunk indices, handed out
// to num_threads threads (0 = hardware concurrency; never more than there are chunks), the
// calling thread included.
template <typename Task>
void ParallelForChunks(int count, int chunk, int num_threads, const Task& task) {
  std::atomic<int> next{0};
  auto work = [&]() {
    for (int begin = next.fetch_add(chunk); begin < count; begin = next.fetch_add(chunk)) {
      task(begin, std::min(count, begin + chunk));
    }
  };
  const int hardware = static_cast<int>(std::thread::hardware_concurrency());
  const int chunks = (count + chunk - 1) / chunk;
  const int threads = std::clamp(num_threads > 0 ? num_threads : hardware, 1, std::max(1, chunks));
  std::vector<std::thread> workers;
  workers.reserve(threads - 1);
  for (int t = 1; t < threads; ++t) workers.emplace_back(work);
  work();
  for (std::thread& worker : workers) worker.join();
}

// The distance to the mesh, negative where the winding number says inside.
double SignedDistanceAt(const MeshDistance& distance, const WindingNumber& winding,
                        const Eigen::Vector3d& p) {
  const double d = distance.Distance(p);
  // The coarse winding number (error < 1e-2) decides unless it is near 1/2.
  double w = std::abs(winding.Evaluate(p, WindingNumber::kCoarseFarFactor));
  if (std::abs(w - 0.5) < kCoarseDecisionMargin) w = std::abs(winding(p));
  return w >= 0.5 ? -d : d;
}

// field->phi at every grid node: the distance, negative where the winding number says inside.
// Nodes are handed out in tasks of kNodesPerTask to num_threads threads (0 = hardware
// concurrency), the calling thread included.
void FillSignedDistances(const MeshDistance& distance, const WindingNumber& winding,
                         int num_threads, SignedDistanceField* field) {
  const int n = field->grid.NumNodes();
  field->phi.assign(n, 0.0);
  ParallelForChunks(n, kNodesPerTask, num_threads, [&](int begin, int end) {
    for (int node = begin; node < end; ++node) {
      field->phi[node] = SignedDistanceAt(distance, winding, field->grid.NodePosition(node));
    }
  });
}

// One cut cell's lattice of n + 1 samples per edge: its corners copied from phi (so that both
// descriptions agree where they meet), the rest measured like the nodes.
void FillCutCellLattice(const MeshDistance& distance, const WindingNumber& winding,
                        const RegularGrid& grid, const std::vector<double>& phi, int cell, int n,
                        double* lattice) {
  const int side = n + 1;
  const std::array<int, 8> nodes = grid.CellNodes(cell);
  const Eigen::Vector3d origin = grid.NodePosition(nodes[0]);
  for (int k = 0; k <= n; ++k) {
    for (int j = 0; j <= n; ++j) {
      for (int i = 0; i <= n; ++i) {
        double& value = lattice[i + side * (j + side * k)];
        if ((i == 0 || i == n) && (j == 0 || j == n) && (k == 0 || k == n)) {
          value = phi[nodes[(i == n) + 2 * (j == n) + 4 * (k == n)]];
          continue;
        }
        value = SignedDistanceAt(distance, winding,
                                 origin + grid.cell_size / n * Eigen::Vector3d(i, j, k));
      }
    }
  }
}

// The cells whose corners differ in sign each get a lattice (FillCutCellLattice), on num_threads
// threads.
void FillCutCellLattices(const MeshDistance& distance, const WindingNumber& winding, int n,
                         int num_threads, SignedDistanceField* field) {
  const RegularGrid& grid = field->grid;
  field->cut_cell_samples = n;
  field->cut_cell_lattice.assign(grid.NumCells(), -1);
  std::vector<int> cut_cells;
  for (int cell = 0; cell < grid.NumCells(); ++cell) {
    int negative = 0;
    for (int node : grid.CellNodes(cell)) negative += field->phi[node] < 0.0;
    if (negative == 0 || negative == 8) continue;
    field->cut_cell_lattice[cell] = static_cast<int>(cut_cells.size());
    cut_cells.push_back(cell);
  }
  const int side = n + 1;
  const int lattice_size = side * side * side;
  field->cut_cell_phi.assign(cut_cells.size() * lattice_size, 0.0);
  ParallelForChunks(
      static_cast<int>(cut_cells.size()), kCutCellsPerTask, num_threads, [&](int begin, int end) {
        for (int t = begin; t < end; ++t) {
          FillCutCellLattice(distance, winding, grid, field->phi, cut_cells[t], n,
                             field->cut_cell_phi.data() + static_cast<size_t>(t) * lattice_size);
        }
      });
}

}  // namespace

Status SignedDistanceOptions::Validate() const {
  if (cells_along_longest_side < 2) {
    return Status::InvalidArgument(Field("cells_along_longest_side") + " = " +
                                   std::to_string(cells_along_longest_side) + ": must be >= 2");
  }
  if (!(cell_size >= 0.0) || !std::isfinite(cell_size)) {
    return Status::InvalidArgument(Field("cell_size") + " = " + std::to_string(cell_size) +
                                   ": must be finite and >= 0 (0 = use cells_along_longest_side)");
  }
  if (padding_cells < 1) {
    return Status::InvalidArgument(Field("padding_cells") + " = " + std::to_string(padding_cells) +
                                   ": must be >= 1");
  }
  if (num_threads < 0) {
    return Status::InvalidArgument(Field("num_threads") + " = " + std::to_string(num_threads) +
                                   ": must be >= 0 (0 = hardware concurrency)");
  }
  if (!IsCutCellSampling(cut_cell_samples)) {
    return Status::InvalidArgument(Field("cut_cell_samples") + " = " +
                                   std::to_string(cut_cell_samples) + ": must be 1, 2, 4 or 8");
  }
  for (int a = 0; a < 3; ++a) {
    if (std::isinf(node_plane[a])) {
      return Status::InvalidArgument(Field("node_plane") + "[" + std::to_string(a) + "] = " +
                                     std::to_string(node_plane[a]) + ": must be finite or NaN");
    }
  }
  return Status::Ok();
}

double SignedDistanceField::Interpolate(const Eigen::Vector3d& p) const {
  Eigen::Vector3d local;
  const int cell = grid.LocateCell(p, &local);
  local = local.cwiseMax(0.0).cwiseMin(1.0);
  const std::array<double, 8> w = TrilinearWeights(local);
  const std::array<int, 8> nodes = grid.CellNodes(cell);
  double value = 0.0;
  for (int c = 0; c < 8; ++c) value += w[c] * phi[nodes[c]];
  return value;
}

std::span<const double> SignedDistanceField::CellLattice(int cell) const {
  if (cut_cell_samples <= 1 || cut_cell_lattice.empty() || cut_cell_lattice[cell] < 0) return {};
  const size_t size =
      static_cast<size_t>(cut_cell_samples + 1) * (cut_cell_samples + 1) * (cut_cell_samples + 1);
  return {cut_cell_phi.data() + cut_cell_lattice[cell] * size, size};
}

Result<SignedDistanceField> ComputeSignedDistanceField(const TriangleMesh& mesh,
                                                       const SignedDistanceOptions& options) {
  SOFTID_RETURN_IF_ERROR(options.Validate());
  SOFTID_RETURN_IF_ERROR(ValidateTriangleMesh(mesh));

  const Eigen::AlignedBox3d bounds = mesh.Bounds();
  const Eigen::Vector3d extent = bounds.sizes();
  SOFTID_ASSIGN_OR_RETURN(const double h, ChooseCellSize(extent, options));
  SignedDistanceField field;
  SOFTID_RETURN_IF_ERROR(LayOutGrid(bounds, extent, h, options, &field.grid));

  SOFTID_ASSIGN_OR_RETURN(const MeshDistance distance, MeshDistance::Create(mesh));
  const WindingNumber winding(mesh);
  FillSignedDistances(distance, winding, options.num_threads, &field);
  if (options.cut_cell_samples > 1) {
    FillCutCellLattices(distance, winding, options.cut_cell_samples, options.num_threads, &field);
  }
  return field;
}

}  // namespace softid::geometry
