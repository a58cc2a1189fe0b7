// magcomp: a term written in the term language: a projection of a signal (see signal.h).
//
//   term       := projection ':' signal
//   projection := field     a body-fixed field ∝ the signal, projected on the Earth-field direction
//                           B̂: 3 columns B̂i·s (9 columns B̂i·s_j for a vector signal such as B)
//               | induced   magnetisation induced by the Earth field, scaled by the signal:
//                           6 columns B̂i·B̂j·|B|·s / bt_scale (ij = xx xy xz yy yz zz)
//               | scalar    added to the scalar reading as it is: 1 column s (3 for a vector)
//
// Examples: field:cur_strb (= current:cur_strb), field:cur_strb|d (= dcurrent:cur_strb),
// field:cur_heat|pow(2)|lp(?) (a heater's thermal drift), field:B|decay(?) (eddy currents that
// decay), field:nrml_acc (structural flex with load factor), scalar:mag_5_uc|d (the scalar's own
// first-order response: time constant = -coefficient).
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "magcomp/core/model/signal.h"
#include "magcomp/core/model/term.h"

namespace magcomp {

enum class Projection { Field, Induced, Scalar };

/// A term of the language. `alias` is the shorthand it was written as (current:X, dcurrent:X,
/// rate:X): its spec and column names stay the shorthand's.
class ExprTerm : public Term {
 public:
  ExprTerm(Projection projection, SignalExpr signal, std::string alias = "");

  std::string spec() const override;
  std::string effect() const override;
  std::vector<std::string> column_names() const override;
  /// The data fields among the sources (not B or Bt).
  std::vector<std::string> required_fields() const override;
  /// 0 for a signal without transforms; -1 otherwise (the transforms run from the flight's start).
  int row_reach() const override { return signal_.transforms.empty() ? 0 : -1; }
  void build(const TermInputs& in, Eigen::Ref<Eigen::MatrixXd> out) const override;

  Projection projection() const { return projection_; }
  const SignalExpr& signal() const { return signal_; }
  /// The spec with every parameter written as '?': terms of one shape differ only in values.
  std::string shape() const;
  /// The signal at every sample of in.data (N x width): the stream's values when the flight holds
  /// them (stream_column()), else the transforms run over the whole flight.
  Eigen::MatrixXd signal_values(const TermInputs& in) const;
  /// Writes the columns for given signal values (N x width).
  void project(const TermInputs& in, const Eigen::MatrixXd& signal,
               Eigen::Ref<Eigen::MatrixXd> out) const;
  /// Name of the column that carries component c of this signal as computed by a stream.
  std::string stream_column(int c) const;
  /// The term with its free parameters replaced, in order, by `values`.
  std::string with_parameters(const std::vector<double>& values) const;
  /// Parameters in physical words and values, e.g. {"lp.time_constant_s", 87.3}.
  std::vector<std::pair<std::string, double>> parameters() const;
  /// The fitted size in words, e.g. "19.2 nT/A" (field of a current), from its coefficients.
  std::string size_in_words(const Eigen::VectorXd& coefficients) const;

 private:
  Projection projection_;
  SignalExpr signal_;
  std::string alias_;
};

/// Parses `field:...`, `induced:...`, `scalar:...` and the shorthands current:, dcurrent:, rate:.
/// Returns nullptr when `spec` is none of these; throws magcomp::Error naming the spec when it is
/// one of them but malformed.
std::unique_ptr<ExprTerm> parse_expr_term(const std::string& spec);

}  // namespace magcomp
