// magcomp: per-row quadratic forms, rows side by side in SIMD lanes (compiled without
// floating-point contraction, so a multiply and an add stay two roundings as in the per-row form).
#include "magcomp/core/quadratic_form.h"

#include <cfloat>
#include <cmath>

namespace magcomp {

namespace {

constexpr Eigen::Index kLanes = 8;  // rows computed together

// The per-row form, as the reference and the fallback.
void per_row(const Eigen::MatrixXd& c, const Eigen::Ref<const Eigen::MatrixXd>& a, double add,
             double* out) {
  Eigen::VectorXd buffer;
  Eigen::RowVectorXd row;
  for (Eigen::Index i = 0; i < a.rows(); ++i) {
    row = a.row(i);
    if (!row.allFinite()) {
      out[i] = NAN;
      continue;
    }
    buffer.noalias() = c * row.transpose();
    out[i] = row.dot(buffer) + add;
  }
}

// Rows [first, first + kLanes) of a (column-major, leading dimension lda), p columns.
// Eigen 3.4's dot product of p doubles in two-double packets (SSE2) sums: two packet accumulators
// over the first p4 = 4 floor(p / 4) products (lane sums s0..s3 for indices = 0..3 mod 4, in
// order), added together lane-wise; then the packet at [p4, p4 + 2) when p mod 4 >= 2; the two
// lanes summed; then the odd last product. Each product is row[r] * (C row)[r], and (C row)[r]
// is sum over j in order of C(r, j) row[j] (the column-major matrix-vector product's order).
#if defined(__GNUC__) && !defined(__clang__)
__attribute__((target_clones("avx2", "default")))
#endif
void lanes(const double* c, Eigen::Index p, const double* a, Eigen::Index lda, double add,
           double* out) {
  const Eigen::Index p2 = 2 * (p / 2), p4 = 4 * (p / 4);
  double s[4][kLanes], tail[2][kLanes], odd[kLanes], b[kLanes], prod[kLanes];
  for (Eigen::Index r = 0; r < p; ++r) {
    const double* ar = a + r * lda;
    for (Eigen::Index i = 0; i < kLanes; ++i) b[i] = c[r] * a[i];  // C(r, 0) a(i, 0)
    for (Eigen::Index j = 1; j < p; ++j) {
      const double crj = c[r + j * p];
      const double* aj = a + j * lda;
      for (Eigen::Index i = 0; i < kLanes; ++i) b[i] = b[i] + crj * aj[i];
    }
    for (Eigen::Index i = 0; i < kLanes; ++i) prod[i] = ar[i] * b[i];
    double* to = r < p4 ? s[r % 4] : r < p2 ? tail[r - p4] : odd;
    if (r < 4 || r >= p4) {
      for (Eigen::Index i = 0; i < kLanes; ++i) to[i] = prod[i];
    } else {
      for (Eigen::Index i = 0; i < kLanes; ++i) to[i] = to[i] + prod[i];
    }
  }
  for (Eigen::Index i = 0; i < kLanes; ++i) {
    double res;
    if (p == 1) {
      res = odd[i];
    } else if (p < 4) {  // one packet
      res = tail[0][i] + tail[1][i];
      if (p == 3) res = res + odd[i];
    } else {
      double lane0 = s[0][i] + s[2][i], lane1 = s[1][i] + s[3][i];
      if (p2 > p4) {
        lane0 = lane0 + tail[0][i];
        lane1 = lane1 + tail[1][i];
      }
      res = lane0 + lane1;
      if (p > p2) res = res + odd[i];
    }
    out[i] = res + add;
  }
}

}  // namespace

void row_quadratic_forms(const Eigen::MatrixXd& c, const Eigen::Ref<const Eigen::MatrixXd>& a,
                         double add, double* out) {
  const Eigen::Index m = a.rows(), p = a.cols();
  constexpr bool kTwoDoublePackets =
      Eigen::internal::packet_traits<double>::size == 2
#ifdef EIGEN_VECTORIZE_FMA
      && false
#endif
      ;
  if (!kTwoDoublePackets || p == 0 || m < kLanes || a.innerStride() != 1) {
    per_row(c, a, add, out);
    return;
  }
  const Eigen::Index full = m - m % kLanes;
  for (Eigen::Index i = 0; i < full; i += kLanes) {
    lanes(c.data(), p, a.data() + i, a.outerStride(), add, out + i);
  }
  if (full < m) per_row(c, a.bottomRows(m - full), add, out + full);
  // A row holding NaN or Inf has no variance (its sums above may hold anything).
  for (Eigen::Index j = 0; j < p; ++j) {
    const double* aj = a.data() + j * a.outerStride();
    for (Eigen::Index i = 0; i < full; ++i) {
      if (!(std::abs(aj[i]) <= DBL_MAX)) out[i] = NAN;
    }
  }
}

}  // namespace magcomp
