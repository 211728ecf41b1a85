#include "core/geometry/signed_distance_field.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <string>
#include <thread>

#include "core/geometry/mesh_distance.h"
#include "core/geometry/winding_number.h"

namespace softid::geometry {
namespace {

constexpr long long kMaxNodes = 1LL << 27;
// Extents within this fraction of a cell above a whole number of cells count as that number [-].
constexpr double kWholeCellTolerance = 1e-3;
constexpr int kNodesPerTask = 512;
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

// field->phi at every grid node: the distance, negative where the winding number says inside.
// Nodes are handed out in tasks of kNodesPerTask to num_threads threads (0 = hardware
// concurrency), the calling thread included.
void FillSignedDistances(const MeshDistance& distance, const WindingNumber& winding,
                         int num_threads, SignedDistanceField* field) {
  const int n = field->grid.NumNodes();
  field->phi.assign(n, 0.0);
  std::atomic<int> next_task{0};
  auto work = [&]() {
    while (true) {
      const int begin = next_task.fetch_add(kNodesPerTask);
      if (begin >= n) return;
      const int end = std::min(n, begin + kNodesPerTask);
      for (int node = begin; node < end; ++node) {
        const Eigen::Vector3d p = field->grid.NodePosition(node);
        const double d = distance.Distance(p);
        // The coarse winding number (error < 1e-2) decides unless it is near 1/2.
        double w = std::abs(winding.Evaluate(p, WindingNumber::kCoarseFarFactor));
        if (std::abs(w - 0.5) < kCoarseDecisionMargin) w = std::abs(winding(p));
        field->phi[node] = w >= 0.5 ? -d : d;
      }
    }
  };
  int threads =
      num_threads > 0 ? num_threads : static_cast<int>(std::thread::hardware_concurrency());
  threads = std::clamp(threads, 1, std::max(1, n / kNodesPerTask));
  std::vector<std::thread> workers;
  workers.reserve(threads - 1);
  for (int t = 1; t < threads; ++t) workers.emplace_back(work);
  work();
  for (std::thread& worker : workers) worker.join();
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
  return field;
}

}  // namespace softid::geometry
