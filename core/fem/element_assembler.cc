#include "core/fem/element_assembler.h"

#include <algorithm>

#include "core/common/check.h"

namespace softid::fem {

ElementAssembler::ElementAssembler(int num_nodes,
                                   const std::vector<std::array<int, 8>>& element_nodes) {
  // Node adjacency (sorted, unique), then the scalar CSC pattern column by column.
  std::vector<std::vector<int>> neighbours(num_nodes);
  for (const auto& nodes : element_nodes) {
    for (int a = 0; a < 8; ++a) {
      for (int b = 0; b < 8; ++b) neighbours[nodes[b]].push_back(nodes[a]);
    }
  }
  size_t nnz = 0;
  for (auto& list : neighbours) {
    std::sort(list.begin(), list.end());
    list.erase(std::unique(list.begin(), list.end()), list.end());
    nnz += 9 * list.size();
  }
  const int n = 3 * num_nodes;
  matrix_.resize(n, n);
  matrix_.resizeNonZeros(static_cast<Eigen::Index>(nnz));
  int* outer = matrix_.outerIndexPtr();
  int* inner = matrix_.innerIndexPtr();
  int pos = 0;
  for (int j = 0; j < num_nodes; ++j) {
    for (int col = 0; col < 3; ++col) {
      outer[3 * j + col] = pos;
      for (int i : neighbours[j]) {
        for (int row = 0; row < 3; ++row) inner[pos++] = 3 * i + row;
      }
    }
  }
  outer[n] = pos;
  SOFTID_DEMAND(static_cast<size_t>(pos) == nnz);

  // Offset of node i's rows in column (3j + col) = outer[3j + col] + 3 * rank of i among j's.
  auto offset_of = [&](int i, int j, int col) {
    const auto& list = neighbours[j];
    const int rank = static_cast<int>(std::lower_bound(list.begin(), list.end(), i) - list.begin());
    return outer[3 * j + col] + 3 * rank;
  };
  block_offsets_.resize(element_nodes.size() * 64 * 3);
  for (size_t e = 0; e < element_nodes.size(); ++e) {
    for (int a = 0; a < 8; ++a) {
      for (int b = 0; b < 8; ++b) {
        for (int col = 0; col < 3; ++col) {
          block_offsets_[(e * 64 + a * 8 + b) * 3 + col] =
              offset_of(element_nodes[e][a], element_nodes[e][b], col);
        }
      }
    }
  }
  node_diagonal_offsets_.resize(static_cast<size_t>(num_nodes) * 3);
  for (int i = 0; i < num_nodes; ++i) {
    for (int col = 0; col < 3; ++col) node_diagonal_offsets_[3 * i + col] = offset_of(i, i, col);
  }
  SetZero();
}

void ElementAssembler::SetZero() {
  SetZero(0, 1);
}

void ElementAssembler::SetZero(int part, int parts) {
  SOFTID_DEMAND(parts >= 1 && part >= 0 && part < parts);
  const Eigen::Index nonzeros = matrix_.nonZeros();
  const Eigen::Index begin = nonzeros * part / parts, end = nonzeros * (part + 1) / parts;
  std::fill(matrix_.valuePtr() + begin, matrix_.valuePtr() + end, 0.0);
}

void ElementAssembler::AddNodeBlock(int node, const Eigen::Matrix3d& block) {
  double* values = matrix_.valuePtr();
  for (int col = 0; col < 3; ++col) {
    double* column = values + node_diagonal_offsets_[3 * node + col];
    for (int row = 0; row < 3; ++row) column[row] += block(row, col);
  }
}

void ElementAssembler::EliminateNode(int node) {
  // Column entries of the node, and the symmetric row entries found through each column.
  const int* outer = matrix_.outerIndexPtr();
  const int* inner = matrix_.innerIndexPtr();
  double* values = matrix_.valuePtr();
  for (int col = 0; col < 3; ++col) {
    const int j = 3 * node + col;
    for (int p = outer[j]; p < outer[j + 1]; ++p) {
      const int i = inner[p];
      values[p] = (i == j) ? 1.0 : 0.0;
      if (i == j) continue;
      // Entry (j, i): column i, row j.
      const int* begin = inner + outer[i];
      const int* end = inner + outer[i + 1];
      const int* hit = std::lower_bound(begin, end, j);
      if (hit != end && *hit == j) values[hit - inner] = 0.0;
    }
  }
}

}  // namespace softid::fem
