#include "core/fem/reduced_precision_factor.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>

#if SOFTID_HALF_PRECISION_FACTOR
#include <immintrin.h>
#endif

#include "core/common/check.h"

namespace softid::fem {
namespace {

// Fortran BLAS (OpenBLAS, which CHOLMOD uses too). The diagonal blocks' triangular solves use
// Eigen instead: OpenBLAS's strsv runs one saxpy call per column, and a preconditioner application
// took 1.72 ms with it against 1.35 ms with Eigen's blocked solve (softid_fem_benchmarks,
// BM_Precondition, one thread).
extern "C" {
void sgemv_(const char* trans, const int* m, const int* n, const float* alpha, const float* a,
            const int* lda, const float* x, const int* incx, const float* beta, float* y,
            const int* incy);
}

#if SOFTID_HALF_PRECISION_FACTOR
// Eight halves from p on, as floats.
__m256 LoadHalves(const StoredBelow* p) {
  return _mm256_cvtph_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(p)));
}

// Columns j to j + 3 of an m-row column-major block h.
std::array<const StoredBelow*, 4> FourColumns(const StoredBelow* h, int m, int j) {
  const StoredBelow* first = h + static_cast<std::ptrdiff_t>(j) * m;
  return {first, first + m, first + 2 * m, first + 3 * m};
}

// y[0, m) = sum_j x_j h[:, j] for an m x n column-major block h (leading dimension m).
void HalfBlockTimes(const StoredBelow* h, int m, int n, const float* x, float* y) {
  std::fill(y, y + m, 0.0f);
  const int m8 = m - m % 8;
  int j = 0;
  for (; j + 4 <= n; j += 4) {
    const auto [c0, c1, c2, c3] = FourColumns(h, m, j);
    const __m256 x0 = _mm256_set1_ps(x[j]), x1 = _mm256_set1_ps(x[j + 1]);
    const __m256 x2 = _mm256_set1_ps(x[j + 2]), x3 = _mm256_set1_ps(x[j + 3]);
    for (int i = 0; i < m8; i += 8) {
      __m256 acc = _mm256_loadu_ps(y + i);
      acc = _mm256_fmadd_ps(LoadHalves(c0 + i), x0, acc);
      acc = _mm256_fmadd_ps(LoadHalves(c1 + i), x1, acc);
      acc = _mm256_fmadd_ps(LoadHalves(c2 + i), x2, acc);
      acc = _mm256_fmadd_ps(LoadHalves(c3 + i), x3, acc);
      _mm256_storeu_ps(y + i, acc);
    }
    for (int i = m8; i < m; ++i) {
      y[i] += _cvtsh_ss(c0[i]) * x[j] + _cvtsh_ss(c1[i]) * x[j + 1] + _cvtsh_ss(c2[i]) * x[j + 2] +
              _cvtsh_ss(c3[i]) * x[j + 3];
    }
  }
  for (; j < n; ++j) {
    const StoredBelow* c0 = h + static_cast<std::ptrdiff_t>(j) * m;
    const __m256 x0 = _mm256_set1_ps(x[j]);
    for (int i = 0; i < m8; i += 8) {
      const __m256 v = LoadHalves(c0 + i);
      _mm256_storeu_ps(y + i, _mm256_fmadd_ps(v, x0, _mm256_loadu_ps(y + i)));
    }
    for (int i = m8; i < m; ++i) y[i] += _cvtsh_ss(c0[i]) * x[j];
  }
}

float HorizontalSum(__m256 v) {
  const __m128 pair = _mm_add_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps(v, 1));
  const __m128 two = _mm_add_ps(pair, _mm_movehl_ps(pair, pair));
  return _mm_cvtss_f32(_mm_add_ss(two, _mm_shuffle_ps(two, two, 1)));
}

// t_j = sum_i h[i, j] x_i, j in [0, n), for an m x n column-major block h (leading dimension m).
void HalfBlockTransposedTimes(const StoredBelow* h, int m, int n, const float* x, float* t) {
  const int m8 = m - m % 8;
  int j = 0;
  for (; j + 4 <= n; j += 4) {
    const auto [c0, c1, c2, c3] = FourColumns(h, m, j);
    __m256 a0 = _mm256_setzero_ps(), a1 = _mm256_setzero_ps();
    __m256 a2 = _mm256_setzero_ps(), a3 = _mm256_setzero_ps();
    for (int i = 0; i < m8; i += 8) {
      const __m256 xv = _mm256_loadu_ps(x + i);
      a0 = _mm256_fmadd_ps(LoadHalves(c0 + i), xv, a0);
      a1 = _mm256_fmadd_ps(LoadHalves(c1 + i), xv, a1);
      a2 = _mm256_fmadd_ps(LoadHalves(c2 + i), xv, a2);
      a3 = _mm256_fmadd_ps(LoadHalves(c3 + i), xv, a3);
    }
    float s0 = HorizontalSum(a0), s1 = HorizontalSum(a1), s2 = HorizontalSum(a2),
          s3 = HorizontalSum(a3);
    for (int i = m8; i < m; ++i) {
      s0 += _cvtsh_ss(c0[i]) * x[i];
      s1 += _cvtsh_ss(c1[i]) * x[i];
      s2 += _cvtsh_ss(c2[i]) * x[i];
      s3 += _cvtsh_ss(c3[i]) * x[i];
    }
    t[j] = s0;
    t[j + 1] = s1;
    t[j + 2] = s2;
    t[j + 3] = s3;
  }
  for (; j < n; ++j) {
    const StoredBelow* c0 = h + static_cast<std::ptrdiff_t>(j) * m;
    __m256 a0 = _mm256_setzero_ps();
    for (int i = 0; i < m8; i += 8) {
      a0 = _mm256_fmadd_ps(LoadHalves(c0 + i), _mm256_loadu_ps(x + i), a0);
    }
    float s0 = HorizontalSum(a0);
    for (int i = m8; i < m; ++i) s0 += _cvtsh_ss(c0[i]) * x[i];
    t[j] = s0;
  }
}

// Stores column values v[0, m) scaled by 1 / scale (rounded to nearest).
void StoreBelowColumn(const double* v, int m, float scale, StoredBelow* out) {
  const float inverse = scale > 0.0f ? 1.0f / scale : 0.0f;
  const __m256 inverse8 = _mm256_set1_ps(inverse);
  int i = 0;
  for (; i + 8 <= m; i += 8) {
    const __m256 lo = _mm256_castps128_ps256(_mm256_cvtpd_ps(_mm256_loadu_pd(v + i)));
    const __m256 both = _mm256_insertf128_ps(lo, _mm256_cvtpd_ps(_mm256_loadu_pd(v + i + 4)), 1);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + i),
                     _mm256_cvtps_ph(_mm256_mul_ps(both, inverse8), _MM_FROUND_TO_NEAREST_INT));
  }
  for (; i < m; ++i)
    out[i] = _cvtss_sh(static_cast<float>(v[i]) * inverse, _MM_FROUND_TO_NEAREST_INT);
}
#else
void StoreBelowColumn(const double* v, int m, float /*scale*/, StoredBelow* out) {
  for (int i = 0; i < m; ++i) out[i] = static_cast<float>(v[i]);
}
#endif

// The supernodal elimination tree, with each subtree's work (~ entries of its factor columns).
struct SupernodeTree {
  std::vector<int> parent;            // -1 at a root
  std::vector<int> first_descendant;  // a subtree is the range [first_descendant, root]
  std::vector<double> work;           // of the subtree rooted at s
  std::vector<std::vector<int>> children;
  double total_work = 0.0;
};

SupernodeTree BuildSupernodeTree(int n, const std::vector<int>& super, const std::vector<int>& pi,
                                 const std::vector<int>& rows) {
  const int nsuper = static_cast<int>(super.size()) - 1;
  std::vector<int> supernode_of(n);
  for (int s = 0; s < nsuper; ++s)
    std::fill(supernode_of.begin() + super[s], supernode_of.begin() + super[s + 1], s);
  // Parent: the supernode of the first row below the diagonal block (rows ascend). CHOLMOD
  // numbers supernodes in postorder, so a subtree is the range [first_descendant, root].
  SupernodeTree tree;
  tree.parent.assign(nsuper, -1);
  tree.first_descendant.resize(nsuper);
  tree.work.resize(nsuper);
  tree.children.resize(nsuper);
  for (int s = 0; s < nsuper; ++s) tree.first_descendant[s] = s;
  for (int s = 0; s < nsuper; ++s) {
    const int ncol = super[s + 1] - super[s], nrow = pi[s + 1] - pi[s];
    tree.work[s] += static_cast<double>(ncol) * nrow;
    if (nrow > ncol) {
      const int p = tree.parent[s] = supernode_of[rows[pi[s] + ncol]];
      SOFTID_DEMAND(p > s);
      tree.work[p] += tree.work[s];
      tree.first_descendant[p] = std::min(tree.first_descendant[p], tree.first_descendant[s]);
      tree.children[p].push_back(s);
    }
  }
  for (int s = 0; s < nsuper; ++s)
    if (tree.parent[s] < 0) tree.total_work += tree.work[s];
  return tree;
}

// Subtrees dealt to `threads` bins, largest first, each to the least loaded; returns the largest
// load.
double DealSubtrees(const SupernodeTree& tree, const std::vector<int>& subtrees, int threads,
                    std::vector<std::vector<int>>* bins) {
  std::vector<int> order = subtrees;
  std::sort(order.begin(), order.end(), [&](int a, int b) {
    return tree.work[a] != tree.work[b] ? tree.work[a] > tree.work[b] : a < b;
  });
  std::vector<double> load(threads, 0.0);
  bins->assign(threads, {});
  for (int s : order) {
    const int m = static_cast<int>(std::min_element(load.begin(), load.end()) - load.begin());
    load[m] += tree.work[s];
    (*bins)[m].push_back(s);
  }
  return *std::max_element(load.begin(), load.end());
}

// The plan's split: the top supernodes (run after the members) and each member's subtrees.
struct SubtreeSplit {
  std::vector<int> top;
  std::vector<std::vector<int>> bins;
};

// Starting from the roots, moves the heaviest subtree to the top (its children join the
// candidates) while that lowers the time of the slowest member plus the top.
SubtreeSplit SplitSubtrees(const SupernodeTree& tree, int threads) {
  const int nsuper = static_cast<int>(tree.parent.size());
  std::vector<int> candidates, top;
  for (int s = 0; s < nsuper; ++s)
    if (tree.parent[s] < 0) candidates.push_back(s);
  double top_work = 0.0;
  std::vector<std::vector<int>> bins;
  double best_time = threads == 1 ? 0.0 : top_work + DealSubtrees(tree, candidates, threads, &bins);
  SubtreeSplit best{top, bins};
  constexpr int kMaxSplits = 64;
  for (int split = 0; threads > 1 && split < kMaxSplits; ++split) {
    const auto heaviest = std::max_element(candidates.begin(), candidates.end(), [&](int a, int b) {
      return tree.work[a] < tree.work[b];
    });
    const int s = *heaviest;
    if (tree.children[s].empty()) break;
    candidates.erase(heaviest);
    candidates.insert(candidates.end(), tree.children[s].begin(), tree.children[s].end());
    top.push_back(s);
    top_work += tree.work[s];
    for (int c : tree.children[s]) top_work -= tree.work[c];
    const double time = top_work + DealSubtrees(tree, candidates, threads, &bins);
    if (time < best_time) {
      best_time = time;
      best = {top, bins};
    }
  }
  return best;
}

}  // namespace

void ReducedPrecisionFactor::Assign(const cholmod_factor& l, int threads) {
  SOFTID_DEMAND(l.is_super && l.is_ll && l.xtype == CHOLMOD_REAL);
  n_ = static_cast<int>(l.n);
  const int nsuper = static_cast<int>(l.nsuper);
  const int* super = static_cast<const int*>(l.super);
  const int* pi = static_cast<const int*>(l.pi);
  const int* px = static_cast<const int*>(l.px);
  super_.assign(super, super + nsuper + 1);
  pi_.assign(pi, pi + nsuper + 1);
  rows_.assign(static_cast<const int*>(l.s), static_cast<const int*>(l.s) + pi[nsuper]);
  perm_.assign(static_cast<const int*>(l.Perm), static_cast<const int*>(l.Perm) + n_);
  const double* x = static_cast<const double*>(l.x);
  diagonal_offset_.assign(nsuper + 1, 0);
  below_offset_.assign(nsuper + 1, 0);
  int max_below = 0, max_columns = 0;
  for (int s = 0; s < nsuper; ++s) {
    const std::ptrdiff_t ncol = super[s + 1] - super[s], nrow = pi[s + 1] - pi[s];
    diagonal_offset_[s + 1] = diagonal_offset_[s] + ncol * ncol;
    below_offset_[s + 1] = below_offset_[s] + ncol * (nrow - ncol);
    max_below = std::max(max_below, static_cast<int>(nrow - ncol));
    max_columns = std::max(max_columns, static_cast<int>(ncol));
  }
  diagonal_values_.resize(static_cast<size_t>(diagonal_offset_[nsuper]));
  below_values_.resize(static_cast<size_t>(below_offset_[nsuper]));
  column_scale_.assign(n_, 1.0f);
  for (int s = 0; s < nsuper; ++s) {
    const int k1 = super[s], ncol = super[s + 1] - k1;
    const int nrow = pi[s + 1] - pi[s], nbelow = nrow - ncol;
    const double* block = x + px[s];  // nrow x ncol, column-major
    float* diagonal = diagonal_values_.data() + diagonal_offset_[s];
    StoredBelow* below = below_values_.data() + below_offset_[s];
    for (int c = 0; c < ncol; ++c) {
      const double* column = block + static_cast<std::ptrdiff_t>(c) * nrow;
      for (int r = 0; r < ncol; ++r) diagonal[c * ncol + r] = static_cast<float>(column[r]);
      float scale = 1.0f;
      if (SOFTID_HALF_PRECISION_FACTOR) {
        double largest = 0.0;
        for (int r = ncol; r < nrow; ++r) largest = std::max(largest, std::abs(column[r]));
        scale = static_cast<float>(largest);
      }
      column_scale_[k1 + c] = scale;
      StoreBelowColumn(column + ncol, nbelow, scale,
                       below + static_cast<std::ptrdiff_t>(c) * nbelow);
    }
  }
  y_.resize(n_);
  max_below_ = std::max(1, max_below);
  max_columns_ = std::max(1, max_columns);
  SetThreads(threads);
}

void ReducedPrecisionFactor::SetThreads(int threads) {
  Plan(std::max(1, threads));
  members_.resize(member_ranges_.size());
  for (Member& member : members_) {
    member.below.resize(max_below_);
    member.columns.resize(max_columns_);
    member.top_updates.assign(n_, 0.0f);
  }
}

void ReducedPrecisionFactor::Solve(const double* b, double* x, ThreadTeam* team) {
  for (int k = 0; k < n_; ++k) y_[k] = static_cast<float>(b[perm_[k]]);
  const int members = static_cast<int>(member_ranges_.size());
  SOFTID_DEMAND(members == 1 || (team != nullptr && team->size() == members));
  // L y = b: the subtrees, then the top.
  const auto forward_subtrees = [&](int m) {
    for (const auto& [first, last] : member_ranges_[m]) Forward(first, last, &members_[m]);
  };
  if (members == 1) {
    forward_subtrees(0);
  } else {
    team->Run(forward_subtrees);
  }
  for (int k : top_columns_) {
    for (Member& member : members_) {
      y_[k] -= member.top_updates[k];
      member.top_updates[k] = 0.0f;
    }
  }
  for (int s : top_) Forward(s, s + 1, &members_[0]);
  // L^T y = y: the top, then the subtrees, backwards.
  for (auto s = top_.rbegin(); s != top_.rend(); ++s) Backward(*s, *s + 1, &members_[0]);
  const auto backward_subtrees = [&](int m) {
    const auto& ranges = member_ranges_[m];
    for (auto range = ranges.rbegin(); range != ranges.rend(); ++range)
      Backward(range->first, range->second, &members_[m]);
  };
  if (members == 1) {
    backward_subtrees(0);
  } else {
    team->Run(backward_subtrees);
  }
  for (int k = 0; k < n_; ++k) x[perm_[k]] = static_cast<double>(y_[k]);
}

void ReducedPrecisionFactor::BelowTimes(int s, int ncol, int nbelow, Member* member) const {
  const int k1 = super_[s];
  const StoredBelow* block = below_values_.data() + below_offset_[s];
  float* below = member->below.data();
#if SOFTID_HALF_PRECISION_FACTOR
  float* scaled = member->columns.data();
  for (int c = 0; c < ncol; ++c) scaled[c] = column_scale_[k1 + c] * y_[k1 + c];
  HalfBlockTimes(block, nbelow, ncol, scaled, below);
#else
  const int one = 1;
  const float plus = 1.0f, zero = 0.0f;
  sgemv_("N", &nbelow, &ncol, &plus, block, &nbelow, y_.data() + k1, &one, &zero, below, &one);
#endif
}

void ReducedPrecisionFactor::SubtractBelowTransposedTimes(int s, int ncol, int nbelow,
                                                          Member* member) {
  const int k1 = super_[s];
  const StoredBelow* block = below_values_.data() + below_offset_[s];
  const float* below = member->below.data();
#if SOFTID_HALF_PRECISION_FACTOR
  float* products = member->columns.data();
  HalfBlockTransposedTimes(block, nbelow, ncol, below, products);
  for (int c = 0; c < ncol; ++c) y_[k1 + c] -= column_scale_[k1 + c] * products[c];
#else
  const int one = 1;
  const float plus = 1.0f, minus = -1.0f;
  sgemv_("T", &nbelow, &ncol, &minus, block, &nbelow, below, &one, &plus, y_.data() + k1, &one);
#endif
}

void ReducedPrecisionFactor::Forward(int first, int last, Member* member) {
  for (int s = first; s < last; ++s) {
    const int k1 = super_[s], ncol = super_[s + 1] - k1;
    const int nrow = pi_[s + 1] - pi_[s], nbelow = nrow - ncol;
    BlockMap(diagonal_values_.data() + diagonal_offset_[s], ncol, ncol)
        .triangularView<Eigen::Lower>()
        .solveInPlace(Eigen::Map<Eigen::VectorXf>(y_.data() + k1, ncol));
    if (nbelow == 0) continue;
    BelowTimes(s, ncol, nbelow, member);
    const float* below = member->below.data();
    const int* rows = rows_.data() + pi_[s] + ncol;
    const int own = own_below_[s];
    for (int i = 0; i < own; ++i) y_[rows[i]] -= below[i];
    float* top = member->top_updates.data();
    for (int i = own; i < nbelow; ++i) top[rows[i]] += below[i];
  }
}

void ReducedPrecisionFactor::Backward(int first, int last, Member* member) {
  for (int s = last - 1; s >= first; --s) {
    const int k1 = super_[s], ncol = super_[s + 1] - k1;
    const int nrow = pi_[s + 1] - pi_[s], nbelow = nrow - ncol;
    if (nbelow > 0) {
      float* below = member->below.data();
      const int* rows = rows_.data() + pi_[s] + ncol;
      for (int i = 0; i < nbelow; ++i) below[i] = y_[rows[i]];
      SubtractBelowTransposedTimes(s, ncol, nbelow, member);
    }
    BlockMap(diagonal_values_.data() + diagonal_offset_[s], ncol, ncol)
        .transpose()
        .triangularView<Eigen::Upper>()
        .solveInPlace(Eigen::Map<Eigen::VectorXf>(y_.data() + k1, ncol));
  }
}

void ReducedPrecisionFactor::Plan(int threads) {
  const int nsuper = static_cast<int>(super_.size()) - 1;
  const SupernodeTree tree = BuildSupernodeTree(n_, super_, pi_, rows_);
  const SubtreeSplit split = SplitSubtrees(tree, threads);
  member_ranges_.assign(threads, {});
  own_below_.assign(nsuper, 0);
  for (int s = 0; s < nsuper; ++s)
    own_below_[s] = (pi_[s + 1] - pi_[s]) - (super_[s + 1] - super_[s]);
  parallel_share_ = 0.0;
  if (threads == 1) {
    member_ranges_[0].push_back({0, nsuper});
    top_.clear();
    top_columns_.clear();
    return;
  }
  for (int m = 0; m < threads; ++m) {
    for (int root : split.bins[m]) {
      parallel_share_ += tree.work[root] / tree.total_work;
      member_ranges_[m].push_back({tree.first_descendant[root], root + 1});
      // Rows below a subtree's columns that lie past its last column belong to the top.
      const int end_column = super_[root + 1];
      for (int s = tree.first_descendant[root]; s <= root; ++s) {
        const int ncol = super_[s + 1] - super_[s];
        const int* rows = rows_.data() + pi_[s] + ncol;
        own_below_[s] = static_cast<int>(
            std::lower_bound(rows, static_cast<const int*>(rows_.data() + pi_[s + 1]), end_column) -
            rows);
      }
    }
    std::sort(member_ranges_[m].begin(), member_ranges_[m].end());
  }
  top_ = split.top;
  std::sort(top_.begin(), top_.end());
  top_columns_.clear();
  for (int s : top_)
    for (int k = super_[s]; k < super_[s + 1]; ++k) top_columns_.push_back(k);
}

}  // namespace softid::fem
