#include "core/fem/element_assembler.h"

#include <gtest/gtest.h>

#include <random>

namespace softid::fem {
namespace {

// In-place assembly on the fixed pattern equals assembling the same blocks from triplets, and
// eliminating a node leaves an identity row and column.
TEST(ElementAssembler, MatchesTripletAssembly) {
  // Two cells side by side sharing a face: nodes 0..11.
  const std::vector<std::array<int, 8>> elements = {{0, 1, 3, 4, 6, 7, 9, 10},
                                                    {1, 2, 4, 5, 7, 8, 10, 11}};
  ElementAssembler assembler(12, elements);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::vector<Eigen::Triplet<double>> triplets;
  for (int e = 0; e < 2; ++e) {
    for (int a = 0; a < 8; ++a) {
      for (int b = 0; b < 8; ++b) {
        Eigen::Matrix3d block;
        for (int i = 0; i < 9; ++i) block(i / 3, i % 3) = uniform(rng);
        assembler.AddBlock(e, a, b, block);
        for (int r = 0; r < 3; ++r) {
          for (int c = 0; c < 3; ++c) {
            triplets.emplace_back(3 * elements[e][a] + r, 3 * elements[e][b] + c, block(r, c));
          }
        }
      }
    }
  }
  Eigen::SparseMatrix<double> expected(36, 36);
  expected.setFromTriplets(triplets.begin(), triplets.end());
  EXPECT_LT((Eigen::MatrixXd(assembler.matrix()) - Eigen::MatrixXd(expected)).norm(), 1e-12);

  assembler.EliminateNode(4);
  const Eigen::MatrixXd dense(assembler.matrix());
  for (int i = 0; i < 36; ++i) {
    for (int d = 0; d < 3; ++d) {
      const double want = (i == 12 + d) ? 1.0 : 0.0;
      EXPECT_EQ(dense(12 + d, i), want);
      EXPECT_EQ(dense(i, 12 + d), want);
    }
  }
}

// Zeroing in parts (one per thread of a team) clears every value exactly once, for any number of
// parts, including more parts than a slice has values.
TEST(ElementAssembler, ZeroingInPartsClearsEveryValue) {
  const std::vector<std::array<int, 8>> elements = {{0, 1, 3, 4, 6, 7, 9, 10},
                                                    {1, 2, 4, 5, 7, 8, 10, 11}};
  for (const int parts : {1, 2, 3, 7, 5000}) {
    ElementAssembler assembler(12, elements);
    double* values = assembler.matrix().valuePtr();
    const Eigen::Index nonzeros = assembler.matrix().nonZeros();
    std::fill(values, values + nonzeros, 1.0);
    for (int part = parts - 1; part >= 1; --part) assembler.SetZero(part, parts);
    // The first part is left: exactly its slice is still set.
    const Eigen::Index first_end = nonzeros / parts;
    for (Eigen::Index k = 0; k < nonzeros; ++k) {
      ASSERT_EQ(values[k], k < first_end ? 1.0 : 0.0) << "parts " << parts << ", value " << k;
    }
    assembler.SetZero(0, parts);
    EXPECT_EQ(assembler.matrix().norm(), 0.0) << "parts " << parts;
  }
  ElementAssembler assembler(12, elements);
  EXPECT_DEATH(assembler.SetZero(2, 2), "");
}

}  // namespace
}  // namespace softid::fem
