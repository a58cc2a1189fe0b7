// magcomp: per-row quadratic forms, rows side by side in SIMD lanes (compiled without
// floating-point contraction, so a multiply and an add stay two roundings as in the per-row form).
#include "magcomp/core/model/quadratic_form.h"

#include <cmath>
#include <vector>

namespace magcomp {

namespace {

constexpr Eigen::Index kLanes =
    32;  // rows computed together (independent sums keep the adders busy)

// The per-row form row by row (the fallback).
void per_row(const Eigen::MatrixXd& c, const Eigen::Ref<const Eigen::MatrixXd>& a, double add,
             double* out) {
  Eigen::VectorXd buffer;
  for (Eigen::Index i = 0; i < a.rows(); ++i)
    out[i] = row_quadratic_form(c, a.row(i), add, &buffer);
}

// Four doubles side by side: each operation is the elementwise IEEE one (two SSE2 instructions,
// or one AVX2 instruction in the avx2 clone); held in registers across the sums.
typedef double Quad __attribute__((vector_size(32)));
constexpr int kQuads = kLanes / 4;

// Always inlined: called out of line (at -O0) from the avx2 clone, a 32-byte vector would cross a
// call between code built for AVX2 and code built without it, whose ABIs pass it differently.
__attribute__((always_inline)) inline Quad load(const double* x) {
  Quad q;
  __builtin_memcpy(&q, x, sizeof q);
  return q;
}

// Rows [0, kLanes) of a (column-major, leading dimension lda), p columns, C p x p column-major.
// Eigen 3.4's dot product of p doubles in two-double packets (SSE2) sums: two packet accumulators
// over the first p4 = 4 floor(p / 4) products (lane sums s0..s3 for indices = 0..3 mod 4, in
// order), added together lane-wise; then the packet at [p4, p4 + 2) when p mod 4 >= 2; the two
// lanes summed; then the odd last product. Each product is row[r] * (C row)[r], and (C row)[r]
// is the sum over j in order of C(r, j) row[j] (the column-major matrix-vector product's order).
#if defined(__GNUC__) && !defined(__clang__)
__attribute__((target_clones("avx2", "default")))
#endif
void lanes(const double* c, Eigen::Index p, const double* a_in, Eigen::Index lda, double add,
           double* out, double* packed) {
  const Eigen::Index p2 = 2 * (p / 2), p4 = 4 * (p / 4);
  // The rows' columns side by side first: in the matrix they lie a column apart (a multiple of
  // 4 KiB for the usual block heights), where they would evict each other from the L1 cache.
  for (Eigen::Index j = 0; j < p; ++j) {
    __builtin_memcpy(packed + j * kLanes, a_in + j * lda, kLanes * sizeof(double));
  }
  const double* a = packed;
  lda = kLanes;
  // x - x is 0 for a finite x and NaN otherwise: a lane whose sum of them is not 0 holds a NaN or
  // an Inf.
  Quad nonfinite[kQuads] = {};
  for (Eigen::Index j = 0; j < p; ++j) {
    for (int q = 0; q < kQuads; ++q) {
      const Quad x = load(a + j * lda + 4 * q);
      nonfinite[q] = nonfinite[q] + (x - x);
    }
  }
  Quad s[4][kQuads], tail[2][kQuads], odd[kQuads];
  for (Eigen::Index r = 0; r < p; ++r) {
    Quad b[kQuads];
    const double cr0 = c[r];
    for (int q = 0; q < kQuads; ++q) b[q] = cr0 * load(a + 4 * q);  // C(r, 0) a(i, 0)
    for (Eigen::Index j = 1; j < p; ++j) {
      const double crj = c[r + j * p];
      const double* aj = a + j * lda;
      for (int q = 0; q < kQuads; ++q) b[q] = b[q] + crj * load(aj + 4 * q);
    }
    const double* ar = a + r * lda;
    Quad* to = r < p4 ? s[r % 4] : r < p2 ? tail[r - p4] : odd;
    for (int q = 0; q < kQuads; ++q) {
      const Quad prod = load(ar + 4 * q) * b[q];
      to[q] = (r < 4 || r >= p4) ? prod : to[q] + prod;
    }
  }
  for (int q = 0; q < kQuads; ++q) {
    Quad res;
    if (p == 1) {
      res = odd[q];
    } else if (p < 4) {  // one packet
      res = tail[0][q] + tail[1][q];
      if (p == 3) res = res + odd[q];
    } else {
      Quad lane0 = s[0][q] + s[2][q], lane1 = s[1][q] + s[3][q];
      if (p2 > p4) {
        lane0 = lane0 + tail[0][q];
        lane1 = lane1 + tail[1][q];
      }
      res = lane0 + lane1;
      if (p > p2) res = res + odd[q];
    }
    res = res + add;
    const Quad nan = {NAN, NAN, NAN, NAN};
    res = nonfinite[q] == 0 ? res : nan;
    __builtin_memcpy(out + 4 * q, &res, sizeof res);
  }
}

}  // namespace

double row_quadratic_form(const Eigen::MatrixXd& c, const Eigen::Ref<const Eigen::RowVectorXd>& row,
                          double add, Eigen::VectorXd* buffer) {
  if (!row.allFinite()) return NAN;
  buffer->noalias() = c * row.transpose();
  return row.dot(*buffer) + add;
}

void row_quadratic_forms(const Eigen::MatrixXd& c, const Eigen::Ref<const Eigen::MatrixXd>& a,
                         double add, double* out) {
  const Eigen::Index m = a.rows(), p = a.cols();
  constexpr bool kTwoDoublePackets = Eigen::internal::packet_traits<double>::size == 2
#ifdef EIGEN_VECTORIZE_FMA
                                     && false
#endif
      ;
  if (!kTwoDoublePackets || p == 0 || m < kLanes || a.innerStride() != 1) {
    per_row(c, a, add, out);
    return;
  }
  const Eigen::Index full = m - m % kLanes;
  std::vector<double> packed(static_cast<size_t>(p * kLanes));
  for (Eigen::Index i = 0; i < full; i += kLanes) {
    lanes(c.data(), p, a.data() + i, a.outerStride(), add, out + i, packed.data());
  }
  if (full < m) per_row(c, a.bottomRows(m - full), add, out + full);
}

}  // namespace magcomp
