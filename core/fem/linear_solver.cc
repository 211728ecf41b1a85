#include "core/fem/linear_solver.h"

#include <Eigen/CholmodSupport>
#include <Eigen/SparseLU>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <mutex>
#include <utility>

#if defined(__F16C__) && defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#define SOFTID_HALF_PRECISION_FACTOR 1
#else
#define SOFTID_HALF_PRECISION_FACTOR 0
#endif

#include "core/common/check.h"
#include "core/fem/numeric_runtime.h"
#include "core/fem/thread_team.h"

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

// CHOLMOD's supernodal factor, with access to its cholmod_factor.
class SupernodalLlt
    : public Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double, Eigen::ColMajor, int>,
                                         Eigen::Lower> {
 public:
  const cholmod_factor& factor() const { return *m_cholmodFactor; }
};

#if SOFTID_HALF_PRECISION_FACTOR
// The below-diagonal blocks of the factor in IEEE half precision (F16C conversions), each column
// scaled by its largest magnitude (so the halves lie in [-1, 1] whatever the problem's units). The
// solves stream these blocks from memory; in halves they take half the bytes of floats.
using StoredBelow = std::uint16_t;

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
// Without F16C the below-diagonal blocks stay in single precision (scale 1) and run on BLAS.
using StoredBelow = float;
void StoreBelowColumn(const double* v, int m, float /*scale*/, StoredBelow* out) {
  for (int i = 0; i < m; ++i) out[i] = static_cast<float>(v[i]);
}
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
  void Assign(const cholmod_factor& l, int threads) {
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

  // Plans the solves for a team of `threads` (>= 1).
  void SetThreads(int threads) {
    Plan(std::max(1, threads));
    members_.resize(member_ranges_.size());
    for (Member& member : members_) {
      member.below.resize(max_below_);
      member.columns.resize(max_columns_);
      member.top_updates.assign(n_, 0.0f);
    }
  }
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
  void Solve(const double* b, double* x, ThreadTeam* team) {
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

 private:
  struct Member {
    std::vector<float> below;        // one supernode's products below its diagonal block
    std::vector<float> columns;      // one supernode's scaled solution entries
    std::vector<float> top_updates;  // forward-solve updates of top columns, summed later
  };

  using BlockMap = Eigen::Map<const Eigen::MatrixXf>;

  // below = B y_s: the block below supernode s's diagonal times its solved entries.
  void BelowTimes(int s, int ncol, int nbelow, Member* member) const {
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

  // y_s -= B^T below.
  void SubtractBelowTransposedTimes(int s, int ncol, int nbelow, Member* member) {
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

  // Forward substitution through supernodes [first, last), in order.
  void Forward(int first, int last, Member* member) {
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

  // Backward substitution through supernodes [first, last), in reverse order.
  void Backward(int first, int last, Member* member) {
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

  // Splits the supernodal elimination tree among `threads` members: starting from the roots,
  // the heaviest subtree is moved to the top (its children join the candidates) while that lowers
  // the time of the slowest member plus the top; candidates go to members largest first.
  void Plan(int threads) {
    const int nsuper = static_cast<int>(super_.size()) - 1;
    std::vector<int> supernode_of(n_);
    for (int s = 0; s < nsuper; ++s)
      std::fill(supernode_of.begin() + super_[s], supernode_of.begin() + super_[s + 1], s);
    // Parent: the supernode of the first row below the diagonal block (rows ascend). CHOLMOD
    // numbers supernodes in postorder, so a subtree is the range [first_descendant, root].
    std::vector<int> parent(nsuper, -1), first_descendant(nsuper);
    std::vector<double> work(nsuper);
    std::vector<std::vector<int>> children(nsuper);
    for (int s = 0; s < nsuper; ++s) first_descendant[s] = s;
    for (int s = 0; s < nsuper; ++s) {
      const int ncol = super_[s + 1] - super_[s], nrow = pi_[s + 1] - pi_[s];
      work[s] += static_cast<double>(ncol) * nrow;
      if (nrow > ncol) {
        parent[s] = supernode_of[rows_[pi_[s] + ncol]];
        SOFTID_DEMAND(parent[s] > s);
        work[parent[s]] += work[s];
        first_descendant[parent[s]] = std::min(first_descendant[parent[s]], first_descendant[s]);
        children[parent[s]].push_back(s);
      }
    }
    // work[s] is now the work of the subtree rooted at s.
    double total_work = 0.0;
    for (int s = 0; s < nsuper; ++s)
      if (parent[s] < 0) total_work += work[s];
    std::vector<int> candidates, top;
    for (int s = 0; s < nsuper; ++s)
      if (parent[s] < 0) candidates.push_back(s);
    double top_work = 0.0;
    const auto assign = [&](const std::vector<int>& subtrees, std::vector<std::vector<int>>* bins) {
      std::vector<int> order = subtrees;
      std::sort(order.begin(), order.end(),
                [&](int a, int b) { return work[a] != work[b] ? work[a] > work[b] : a < b; });
      std::vector<double> load(threads, 0.0);
      bins->assign(threads, {});
      for (int s : order) {
        const int m = static_cast<int>(std::min_element(load.begin(), load.end()) - load.begin());
        load[m] += work[s];
        (*bins)[m].push_back(s);
      }
      return *std::max_element(load.begin(), load.end());
    };
    std::vector<std::vector<int>> bins;
    double best_time = threads == 1 ? 0.0 : top_work + assign(candidates, &bins);
    std::vector<int> best_top = top;
    std::vector<std::vector<int>> best_bins = bins;
    constexpr int kMaxSplits = 64;
    for (int split = 0; threads > 1 && split < kMaxSplits; ++split) {
      const auto heaviest = std::max_element(candidates.begin(), candidates.end(),
                                             [&](int a, int b) { return work[a] < work[b]; });
      const int s = *heaviest;
      if (children[s].empty()) break;
      candidates.erase(heaviest);
      candidates.insert(candidates.end(), children[s].begin(), children[s].end());
      top.push_back(s);
      top_work += work[s];
      for (int c : children[s]) top_work -= work[c];
      const double time = top_work + assign(candidates, &bins);
      if (time < best_time) {
        best_time = time;
        best_top = top;
        best_bins = bins;
      }
    }
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
      for (int root : best_bins[m]) {
        parallel_share_ += work[root] / total_work;
        member_ranges_[m].push_back({first_descendant[root], root + 1});
        // Rows below a subtree's columns that lie past its last column belong to the top.
        const int end_column = super_[root + 1];
        for (int s = first_descendant[root]; s <= root; ++s) {
          const int ncol = super_[s + 1] - super_[s];
          const int* rows = rows_.data() + pi_[s] + ncol;
          own_below_[s] = static_cast<int>(
              std::lower_bound(rows, static_cast<const int*>(rows_.data() + pi_[s + 1]),
                               end_column) -
              rows);
        }
      }
      std::sort(member_ranges_[m].begin(), member_ranges_[m].end());
    }
    top_ = best_top;
    std::sort(top_.begin(), top_.end());
    top_columns_.clear();
    for (int s : top_)
      for (int k = super_[s]; k < super_[s + 1]; ++k) top_columns_.push_back(k);
  }

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

}  // namespace

struct LinearSolver::Factor {
  SupernodalLlt llt;
  // From CHOLMOD's symbolic analysis: flops of one numeric factorisation and nonzeros of L.
  double flops = 0.0;
  double factor_nonzeros = 0.0;
};

struct LinearSolver::FactorSnapshot {
  ReducedPrecisionFactor reduced;
  Eigen::Matrix3d reference_rotation = Eigen::Matrix3d::Identity();
  double factor_nonzeros = 0.0;
  // Work of the factorisation that made it, including failed shifted attempts (work-model units).
  double factor_work = 0.0;
};

namespace {
// Work model of the ski-rental rule (RefactorPays), in "memory-bound flops": the flops of sparse
// products, triangular solves and vector updates, which all run at about the same rate (bounded by
// memory traffic). A factorisation's flops run as dense BLAS-3 blocks, several times faster;
// kFactorFlopWeight converts them. Measured on the idle 2-core AMD EPYC dev host (OpenBLAS 0.3.21,
// CHOLMOD 3.0.14 with its OpenMP regions serialised, torus-drop at 3100 cells: 12.9k unknowns,
// nnz(A) 0.85e6, nnz(L) 3.5e6, 1.48e9 factorisation flops): Factorize 90-100 ms (~16 GFlop/s),
// one preconditioner application 1.4 ms, one product with A 0.6 ms: a factorisation costs ~45
// iterations, which the weight 0.28 reproduces (0.15 and 0.4 measured no better in bench). The
// rule only needs the ratio to within a factor of ~1.5: a wrong weight shifts the balance between
// refactorisations and extra iterations, never the result's accuracy.
constexpr double kFactorFlopWeight = 0.28;
// The solves run on the reduced-precision copy of L: in single precision they measured 1.7x
// faster than CHOLMOD's double solves on the same host and problem (4.3 vs 7.5 ms under the same
// load), with the blocks below the diagonal in half precision another ~1.4x (BM_Precondition,
// interleaved runs: 0.75-0.9 vs 1.2 ms). With the weight 0.6 of single precision the rule
// refactorised as before, now that iterations are cheaper too often: 0.4 ran pillow-ramp (1 s),
// ball-bounce (0.5 s) and torus-drop's impact (0.3 s) 21 %, 12 % and 3 % faster, torus-drop over
// 1 s 30 % slower (a factor taken at the impact then served its rest).
constexpr double kReducedPrecisionSolveWeight = 0.4;
// Forming the symmetric part and CHOLMOD's permuted transpose before each factorisation:
// ~10 memory-bound flops per entry of A.
constexpr double kFactorWorkPerMatrixEntry = 10.0;

}  // namespace

LinearSolver::LinearSolver() {
  ConfigureNumericRuntime();
}
LinearSolver::~LinearSolver() {
  FinishFactorize();
}

double LinearSolver::ParallelShare() const {
  return current_ != nullptr ? current_->reduced.parallel_share() : 0.0;
}

void LinearSolver::SetThreadTeam(ThreadTeam* team) {
  FinishFactorize();
  team_ = team;
  const int threads = team != nullptr ? team->size() : 1;
  if (current_ != nullptr && current_->reduced.threads() != threads)
    current_->reduced.SetThreads(threads);
}

void LinearSolver::UseFactor(const std::shared_ptr<FactorSnapshot>& factor) {
  if (factor == nullptr || factor == current_) return;
  DiscardFactorize();
  current_ = factor;
  const int threads = team_ != nullptr ? team_->size() : 1;
  if (current_->reduced.threads() != threads) current_->reduced.SetThreads(threads);
  RestartRefactorRule();
}

size_t LinearSolver::FactorBytes(const FactorSnapshot& factor) {
  return factor.reduced.bytes();
}

void LinearSolver::RestartRefactorRule() {
  baseline_iterations_ = -1;
  excess_work_ = 0.0;
}
LinearSolver::LinearSolver(LinearSolver&&) noexcept = default;
LinearSolver& LinearSolver::operator=(LinearSolver&&) noexcept = default;

bool LinearSolver::HasFactor() const {
  return current_ != nullptr;
}

bool LinearSolver::RefactorPays() const {
  return current_ != nullptr && excess_work_ > current_->factor_work;
}

bool LinearSolver::Pattern::Matches(const Matrix& a) const {
  return a.cols() + 1 == static_cast<Eigen::Index>(outer.size()) &&
         a.nonZeros() == static_cast<Eigen::Index>(inner.size()) &&
         std::equal(outer.begin(), outer.end(), a.outerIndexPtr()) &&
         std::equal(inner.begin(), inner.end(), a.innerIndexPtr());
}

void LinearSolver::Pattern::Assign(const Matrix& a) {
  outer.assign(a.outerIndexPtr(), a.outerIndexPtr() + a.cols() + 1);
  inner.assign(a.innerIndexPtr(), a.innerIndexPtr() + a.nonZeros());
}

void LinearSolver::SymmetricPart(const Matrix& a, Symmetry symmetry, Matrix* out) {
  // The consistent tangent is not symmetric; its symmetric part is what a Cholesky factor can
  // approximate (the lower triangle alone can be far from positive definite).
  SOFTID_ASSERT(symmetry == Symmetry::kGeneral ||
                (a - Matrix(a.transpose())).norm() <= 1e-12 * a.norm());
  // Assigning to a matrix of the same size and pattern reuses its storage: a fresh ~10 MB copy
  // cost ~40 ms of first-touch page faults per factorisation on the dev VM (~14 us per page).
  *out = a;
  if (symmetry == Symmetry::kSymmetric) return;
  // (a + a^T) / 2 in place, through the position of each entry's transpose (the assembly's
  // pattern is structurally symmetric; computed once per pattern).
  if (!transposed_pattern_.Matches(a)) {
    transposed_pattern_.Assign(a);
    transpose_position_.assign(a.nonZeros(), -1);
    const int* outer = a.outerIndexPtr();
    const int* inner = a.innerIndexPtr();
    for (int j = 0; j < a.cols(); ++j) {
      for (int p = outer[j]; p < outer[j + 1]; ++p) {
        const int i = inner[p];  // entry (i, j); its transpose (j, i) is in column i
        const int* begin = inner + outer[i];
        const int* end = inner + outer[i + 1];
        const int* hit = std::lower_bound(begin, end, j);
        if (hit != end && *hit == j) transpose_position_[p] = static_cast<int>(hit - inner);
      }
    }
    structurally_symmetric_ = std::find(transpose_position_.begin(), transpose_position_.end(),
                                        -1) == transpose_position_.end();
  }
  if (!structurally_symmetric_ || !a.isCompressed()) {
    *out = 0.5 * (a + Matrix(a.transpose()));
    return;
  }
  const double* values = a.valuePtr();
  double* symmetric = out->valuePtr();
  for (Eigen::Index p = 0; p < a.nonZeros(); ++p)
    symmetric[p] = 0.5 * (values[p] + values[transpose_position_[p]]);
}

void LinearSolver::PrepareWorkspace(const Matrix& symmetric) {
  // The assembly pattern is fixed, so the fill-reducing ordering and symbolic analysis (METIS
  // dominates a factorisation at ~10^4 unknowns) are done once and reused.
  if (!analysed_pattern_.Matches(symmetric)) {
    analysed_pattern_.Assign(symmetric);
    workspace_.reset();  // analysed for another pattern (the current factor still preconditions)
  }
  if (workspace_ == nullptr) {
    workspace_ = std::make_unique<Factor>();
    workspace_->llt.cholmod().print = 0;  // failures are handled below, not printed to stderr
    workspace_->llt.analyzePattern(symmetric);
    workspace_->flops = workspace_->llt.cholmod().fl;
    workspace_->factor_nonzeros = workspace_->llt.cholmod().lnz;
  }
}

int LinearSolver::FactorNumerically(const Matrix& symmetric, int threads, Factor* workspace,
                                    FactorSnapshot* fresh) {
  SupernodalLlt& llt = workspace->llt;
  llt.setShift(0.0);
  llt.factorize(symmetric);
  int attempts = 1;
  // Under strong compression the consistent tangent's geometric part makes the matrix indefinite.
  // As a preconditioner a factor of A + shift I serves as well: try growing shifts relative to the
  // mean diagonal.
  const double mean_diagonal = symmetric.diagonal().cwiseAbs().mean();
  for (double relative_shift : {1e-4, 1e-2, 1e-1, 1.0}) {
    if (llt.info() == Eigen::Success) break;
    llt.setShift(relative_shift * mean_diagonal);
    llt.factorize(symmetric);
    ++attempts;
  }
  if (llt.info() != Eigen::Success) return -attempts;
  fresh->reduced.Assign(llt.factor(), threads);
  fresh->factor_nonzeros = workspace->factor_nonzeros;
  return attempts;
}

void LinearSolver::Adopt(std::shared_ptr<FactorSnapshot> fresh, const Eigen::Matrix3d& rotation,
                         int attempts, Eigen::Index matrix_nonzeros) {
  fresh->reference_rotation = rotation;
  // A failed attempt stops at its first non-positive pivot; counting it in full errs towards
  // keeping a factor that was hard to get.
  fresh->factor_work = attempts * kFactorFlopWeight * workspace_->flops +
                       kFactorWorkPerMatrixEntry * static_cast<double>(matrix_nonzeros);
  current_ = std::move(fresh);
  ++num_factorizations_;
  RestartRefactorRule();
}

Status LinearSolver::Factorize(const Matrix& a, const Eigen::Matrix3d& rotation,
                               Symmetry symmetry) {
  DiscardFactorize();  // replaced at once: computing or adopting it would be wasted
  SymmetricPart(a, symmetry, &factor_input_);
  const Matrix& symmetric = factor_input_;
  PrepareWorkspace(symmetric);
  auto fresh = std::make_shared<FactorSnapshot>();
  const int attempts = FactorNumerically(symmetric, team_ != nullptr ? team_->size() : 1,
                                         workspace_.get(), fresh.get());
  if (attempts < 0) {
    return Status::FailedPrecondition(
        "step matrix is far from positive definite (Cholesky failed)");
  }
  Adopt(std::move(fresh), rotation, attempts, a.nonZeros());
  return Status::Ok();
}

// A factorisation StartFactorize began, owned by the solver until FinishFactorize: the matrix (a
// copy: the caller's changes on) and the outcome, written by the background thread only, if it
// runs in the background (on a team; else FinishFactorize computes it). Destroying it waits for
// the job (a solver moved onto or destroyed never leaves it running on freed memory; pending_ is
// declared before the workspace, so a move assignment joins before it replaces it).
struct LinearSolver::PendingFactorization {
  explicit PendingFactorization(ThreadTeam* team) : team(team) {}
  ~PendingFactorization() {
    if (team != nullptr) team->WaitForBackground();
  }
  PendingFactorization(const PendingFactorization&) = delete;
  PendingFactorization& operator=(const PendingFactorization&) = delete;
  ThreadTeam* team;  // null: not in the background
  Matrix symmetric;
  Eigen::Matrix3d rotation;
  Eigen::Index matrix_nonzeros = 0;
  std::shared_ptr<FactorSnapshot> fresh = std::make_shared<FactorSnapshot>();
  int attempts = 0;  // negative: failed
  // For FinishFactorizeWhenDue: the factorisation's work (one attempt) and the solver's work and
  // calls since it started, in work-model units.
  double expected_work = 0.0;
  double overlapped_work = 0.0;
  int calls = 0;
};

Status LinearSolver::StartFactorize(const Matrix& a, const Eigen::Matrix3d& rotation,
                                    Symmetry symmetry) {
  FinishFactorize();
  const bool background = team_ != nullptr && team_->size() >= 2;
  pending_ = std::make_unique<PendingFactorization>(background ? team_ : nullptr);
  // The pending record borrows factor_input_'s storage until FinishFactorize.
  pending_->symmetric.swap(factor_input_);
  SymmetricPart(a, symmetry, &pending_->symmetric);
  pending_->rotation = rotation;
  pending_->matrix_nonzeros = a.nonZeros();
  PrepareWorkspace(pending_->symmetric);
  pending_->expected_work = kFactorFlopWeight * workspace_->flops +
                            kFactorWorkPerMatrixEntry * static_cast<double>(a.nonZeros());
  // On one thread FinishFactorize computes it: the factor is adopted at the same point either way,
  // so a run's Newton iterates do not depend on the number of threads.
  if (!background) return Status::Ok();
  // The job touches only the pending record and the workspace, both on the heap and left alone
  // by the solver until FinishFactorize joins it.
  PendingFactorization* pending = pending_.get();
  Factor* workspace = workspace_.get();
  const int threads = team_->size();
  team_->StartBackground([pending, workspace, threads] {
    try {
      pending->attempts =
          FactorNumerically(pending->symmetric, threads, workspace, pending->fresh.get());
    } catch (const std::exception&) {
      pending->attempts = -1;  // out of memory, say: the previous factor stays
    }
  });
  return Status::Ok();
}

void LinearSolver::DiscardFactorize() {
  if (pending_ == nullptr) return;
  if (pending_->team != nullptr) pending_->team->WaitForBackground();
  factor_input_.swap(pending_->symmetric);
  pending_.reset();
}

bool LinearSolver::FinishFactorizeWhenDue(int max_calls) {
  if (pending_ == nullptr) return false;
  ++pending_->calls;
  if (pending_->overlapped_work < pending_->expected_work && pending_->calls < max_calls)
    return false;
  return FinishFactorize();
}

bool LinearSolver::FinishFactorize() {
  if (pending_ == nullptr) return false;
  if (pending_->team != nullptr) {
    pending_->team->WaitForBackground();
  } else {
    pending_->attempts =
        FactorNumerically(pending_->symmetric, team_ != nullptr ? team_->size() : 1,
                          workspace_.get(), pending_->fresh.get());
  }
  const std::unique_ptr<PendingFactorization> pending = std::move(pending_);
  factor_input_.swap(pending->symmetric);
  if (pending->attempts < 0) return false;
  Adopt(std::move(pending->fresh), pending->rotation, pending->attempts, pending->matrix_nonzeros);
  return true;
}

namespace {
// y_i = Q x_i for every 3-block.
void RotateBlocks(const Eigen::Matrix3d& q, const Eigen::Ref<const Eigen::VectorXd>& x,
                  Eigen::VectorXd* y) {
  const Eigen::Index n = x.size() / 3;
  for (Eigen::Index i = 0; i < n; ++i) y->segment<3>(3 * i).noalias() = q * x.segment<3>(3 * i);
}
}  // namespace

void LinearSolver::ApplyPreconditioner(const Eigen::Ref<const Eigen::VectorXd>& r,
                                       Eigen::VectorXd* z) {
  RotateBlocks(preconditioner_rotation_.transpose(), r, &rotated_);
  current_->reduced.Solve(rotated_.data(), rotated_.data(), team_);
  RotateBlocks(preconditioner_rotation_, rotated_, z);
}

void LinearSolver::Precondition(const Eigen::VectorXd& b, const Eigen::Matrix3d& rotation,
                                Eigen::VectorXd* x) {
  SOFTID_DEMAND(HasFactor());
  rotated_.resize(b.size());
  x->resize(b.size());
  preconditioner_rotation_ = rotation * current_->reference_rotation.transpose();
  ApplyPreconditioner(b, x);
  if (pending_ != nullptr)
    pending_->overlapped_work += kReducedPrecisionSolveWeight * 4.0 * current_->factor_nonzeros;
}

namespace {
// b = 0: x = 0 solves op(a) x = b exactly.
LinearSolver::Summary SolvedByZero(Eigen::VectorXd* x) {
  x->setZero();
  LinearSolver::Summary summary;
  summary.relative_residual = 0.0;
  summary.converged = true;
  return summary;
}
}  // namespace

LinearSolver::Summary LinearSolver::SolveDirect(const Matrix& a, const Eigen::VectorXd& b,
                                                const Options& options, Eigen::VectorXd* x,
                                                Operator op) {
  Summary summary;
  const double b_norm = b.norm();
  if (b_norm == 0.0) return SolvedByZero(x);
  Eigen::SparseLU<Matrix, Eigen::COLAMDOrdering<int>> lu;
  if (op == Operator::kTransposed) {
    const Matrix transposed = a.transpose();
    lu.compute(transposed);
  } else {
    lu.compute(a);
  }
  if (lu.info() != Eigen::Success) return summary;
  *x = lu.solve(b);
  if (lu.info() != Eigen::Success || !x->allFinite()) return summary;
  summary.iterations = 1;
  const Eigen::VectorXd residual = op == Operator::kTransposed
                                       ? Eigen::VectorXd(b - a.transpose() * *x)
                                       : Eigen::VectorXd(b - a * *x);
  summary.relative_residual = residual.norm() / b_norm;
  summary.converged = summary.relative_residual <= options.relative_tolerance;
  return summary;
}

// Relative tolerances at and above which GMRES trusts its residual recurrence (see Solve).
constexpr double kRecurrenceTrustedTolerance = 1e-8;

LinearSolver::Summary LinearSolver::Solve(const Matrix& a, const Eigen::VectorXd& b,
                                          const Eigen::Matrix3d& rotation, const Options& options,
                                          Eigen::VectorXd* x, Operator op) {
  matrix_operator_.Bind(a, op == Operator::kTransposed, team_);
  return Solve(matrix_operator_, b, rotation, options, x);
}

LinearSolver::Summary LinearSolver::Solve(LinearOperator& a, const Eigen::VectorXd& b,
                                          const Eigen::Matrix3d& rotation, const Options& options,
                                          Eigen::VectorXd* x) {
  SOFTID_DEMAND(HasFactor());
  SOFTID_DEMAND(a.size() == b.size());
  Summary summary;
  const Eigen::Index n = b.size();
  const int m = std::max(1, options.restart);
  if (basis_.rows() != n || basis_.cols() != m + 1) {
    basis_.resize(n, m + 1);
    preconditioned_.resize(n, m);
    hessenberg_.resize(m + 1, m);
    givens_c_.resize(m);
    givens_s_.resize(m);
    g_.resize(m + 1);
  }
  r_.resize(n);
  w_.resize(n);
  rotated_.resize(n);
  preconditioner_rotation_ = rotation * current_->reference_rotation.transpose();

  const double b_norm = b.norm();
  if (b_norm == 0.0) return SolvedByZero(x);
  // Work of this solve (see kFactorFlopWeight): per iteration a preconditioner application (two
  // triangular solves, 2 nnz(L) flops each, and two block rotations), a product with A, and the
  // Gram-Schmidt and update vector operations, which grow with the basis.
  const double nd = static_cast<double>(n);
  const double product_work = a.ApplyWork();
  const double iteration_work = kReducedPrecisionSolveWeight * 4.0 * current_->factor_nonzeros +
                                2.0 * 15.0 / 3.0 * nd + product_work + 8.0 * nd;
  double work = 0.0;
  double residual = 0.0;
  // A zero initial guess (Newton's first solve of a step) has the residual b: no product.
  bool residual_is_b = x->isZero(0.0);
  while (true) {
    if (residual_is_b) {
      r_ = b;
      residual_is_b = false;
    } else {
      a.Apply(*x, &r_);
      r_ = b - r_;
      work += product_work + 3.0 * nd;
    }
    const double beta = r_.norm();
    residual = beta / b_norm;
    if (residual <= options.relative_tolerance || summary.iterations >= options.max_iterations)
      break;
    basis_.col(0) = r_ / beta;
    g_.setZero();
    g_[0] = beta;
    int j = 0;
    for (; j < m && summary.iterations < options.max_iterations; ++j) {
      ++summary.iterations;
      work += iteration_work + 4.0 * nd * (j + 1);
      ApplyPreconditioner(basis_.col(j), &w_);
      preconditioned_.col(j) = w_;
      a.Apply(preconditioned_.col(j), &w_);
      for (int i = 0; i <= j; ++i) {  // modified Gram-Schmidt
        hessenberg_(i, j) = w_.dot(basis_.col(i));
        w_ -= hessenberg_(i, j) * basis_.col(i);
      }
      const double h_next = w_.norm();
      hessenberg_(j + 1, j) = h_next;
      for (int i = 0; i < j; ++i) {  // previous Givens rotations
        const double t = givens_c_[i] * hessenberg_(i, j) + givens_s_[i] * hessenberg_(i + 1, j);
        hessenberg_(i + 1, j) =
            -givens_s_[i] * hessenberg_(i, j) + givens_c_[i] * hessenberg_(i + 1, j);
        hessenberg_(i, j) = t;
      }
      const double denom = std::hypot(hessenberg_(j, j), h_next);
      givens_c_[j] = denom > 0.0 ? hessenberg_(j, j) / denom : 1.0;
      givens_s_[j] = denom > 0.0 ? h_next / denom : 0.0;
      hessenberg_(j, j) = denom;
      hessenberg_(j + 1, j) = 0.0;
      g_[j + 1] = -givens_s_[j] * g_[j];
      g_[j] = givens_c_[j] * g_[j];
      residual = std::abs(g_[j + 1]) / b_norm;
      if (h_next > 0.0) basis_.col(j + 1) = w_ / h_next;
      if (residual <= options.relative_tolerance || h_next == 0.0) {
        ++j;
        break;
      }
    }
    // x += Z y with H y = g (upper triangular, j x j).
    const Eigen::VectorXd y =
        hessenberg_.topLeftCorner(j, j).triangularView<Eigen::Upper>().solve(g_.head(j));
    x->noalias() += preconditioned_.leftCols(j) * y;
    work += 2.0 * nd * j;
    if (residual <= options.relative_tolerance) {
      // Flexible GMRES keeps A Z = V H to round-off (Z is stored, the products are in double),
      // so the recurrence's residual is the true one up to ~1e-14 relative: a product to check
      // it only pays for tolerances near that (the gradient tests' 1e-12).
      if (options.relative_tolerance >= kRecurrenceTrustedTolerance) break;
      a.Apply(*x, &r_);  // true residual (the recurrence can drift)
      r_ = b - r_;
      work += product_work + 3.0 * nd;
      residual = r_.norm() / b_norm;
      if (residual <= 10.0 * options.relative_tolerance) break;
    }
  }
  summary.relative_residual = residual;
  summary.converged = residual <= 10.0 * options.relative_tolerance;
  if (pending_ != nullptr) pending_->overlapped_work += work;
  if (baseline_iterations_ < 0) baseline_iterations_ = summary.iterations;
  if (summary.iterations > baseline_iterations_) {
    excess_work_ += work * (summary.iterations - baseline_iterations_) / summary.iterations;
  }
  return summary;
}

}  // namespace softid::fem
