// A reduced-precision copy of CHOLMOD's supernodal factor and its triangular solves: the
// preconditioner LinearSolver's GMRES applies (internal to core/fem).
#pragma once

#include <cholmod.h>

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include "core/fem/thread_team.h"

// Half precision needs the F16C conversions (and AVX2/FMA for the kernels around them).
#if defined(__F16C__) && defined(__AVX2__) && defined(__FMA__)
#define SOFTID_HALF_PRECISION_FACTOR 1
#else
#define SOFTID_HALF_PRECISION_FACTOR 0
#endif

namespace softid::fem {

#if SOFTID_HALF_PRECISION_FACTOR
// The below-diagonal blocks of the factor in IEEE half precision (F16C conversions), each column
// scaled by its largest magnitude (so the halves lie in [-1, 1] whatever the problem's units). The
// solves stream these blocks from memory; in halves they take half the bytes of floats.
using StoredBelow = std::uint16_t;
#else
// Without F16C the below-diagonal blocks stay in single precision (scale 1) and run on BLAS.
using StoredBelow = float;
#endif

// A reduced-precision copy of a supernodal factor L (L L^T = A(p, p)) and its two triangular
// solves. The solves stream all of L from memory and dominate GMRES: the diagonal blocks are
// kept in single precision and the blocks below them, most of L (~75 % at 3,100 cells), in half
// precision where the CPU converts halves (F16C): 9 instead of 34 MB for the double factor at
// 12.9k unknowns. As a preconditioner it loses little: GMRES keeps the preconditioned basis
// (flexible GMRES), so the solution's accuracy comes from the double products with A alone.
//
// On a team of threads the solves split the supernodal elimination tree: each member takes whole
// subtrees (about equal work, contiguous ranges in CHOLMOD's postorder), the rest (the top
// separators, ~10 % of L on the torus at 3,100 cells) runs on one thread. A subtree's columns only
// update its own columns and its ancestors', which are top columns, so in the forward solve each
// member accumulates its updates of top columns privately and they are summed in member order
// afterwards; the backward solve only reads top columns. The result is independent of timing.
class ReducedPrecisionFactor {
 public:
  void Assign(const cholmod_factor& l, int threads);

  // Plans the solves for a team of `threads` (>= 1).
  void SetThreads(int threads);
  int threads() const { return static_cast<int>(member_ranges_.size()); }
  // Memory held [bytes].
  size_t bytes() const {
    size_t total =
        sizeof(float) * (diagonal_values_.capacity() + column_scale_.capacity() + y_.capacity()) +
        sizeof(StoredBelow) * below_values_.capacity() +
        sizeof(int) * (super_.capacity() + pi_.capacity() + rows_.capacity() + perm_.capacity() +
                       own_below_.capacity());
    for (const Member& member : members_)
      total += sizeof(float) * (member.below.capacity() + member.columns.capacity() +
                                member.top_updates.capacity());
    return total;
  }
  // Share of L's entries the members solve concurrently (0 on one thread).
  double parallel_share() const { return parallel_share_; }

  // x = A^-1 b (both may alias). team: null or of the size Assign planned for.
  void Solve(const double* b, double* x, ThreadTeam* team);

 private:
  struct Member {
    std::vector<float> below;        // one supernode's products below its diagonal block
    std::vector<float> columns;      // one supernode's scaled solution entries
    std::vector<float> top_updates;  // forward-solve updates of top columns, summed later
  };

  using BlockMap = Eigen::Map<const Eigen::MatrixXf>;

  // below = B y_s: the block below supernode s's diagonal times its solved entries.
  void BelowTimes(int s, int ncol, int nbelow, Member* member) const;

  // y_s -= B^T below.
  void SubtractBelowTransposedTimes(int s, int ncol, int nbelow, Member* member);

  // Forward substitution through supernodes [first, last), in order.
  void Forward(int first, int last, Member* member);

  // Backward substitution through supernodes [first, last), in reverse order.
  void Backward(int first, int last, Member* member);

  // Splits the supernodal elimination tree among `threads` members: starting from the roots,
  // the heaviest subtree is moved to the top (its children join the candidates) while that lowers
  // the time of the slowest member plus the top; candidates go to members largest first.
  void Plan(int threads);

  int n_ = 0, max_below_ = 1, max_columns_ = 1;
  std::vector<int> super_, pi_, rows_, perm_;
  // Per supernode: its diagonal block (ncol x ncol, single precision) and the block below it
  // (nbelow x ncol, StoredBelow, column c scaled by column_scale_[first column + c]), both
  // column-major, at these offsets.
  std::vector<std::ptrdiff_t> diagonal_offset_, below_offset_;
  std::vector<float> diagonal_values_;
  std::vector<StoredBelow> below_values_;
  std::vector<float> column_scale_;
  std::vector<float> y_;
  // The plan: per member its subtrees as supernode ranges [first, last), ascending; the top
  // supernodes (ascending) and their columns; per supernode the number of rows below its diagonal
  // block that lie in its own subtree (all of them for top supernodes).
  std::vector<std::vector<std::pair<int, int>>> member_ranges_;
  std::vector<int> top_, top_columns_, own_below_;
  double parallel_share_ = 0.0;
  std::vector<Member> members_;
};

}  // namespace softid::fem
