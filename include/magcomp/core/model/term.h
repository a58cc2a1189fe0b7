// magcomp: a compensation model term = one physical effect that builds its own regressor columns.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "magcomp/core/io/flight_data.h"

namespace magcomp {

/// What every term builds its columns from: the flight, and the vector magnetometer already
/// derived into the quantities the Tolles-Lawson family uses. All fields in nT, sensor frame.
struct TermInputs {
  const FlightData* data = nullptr;
  Eigen::MatrixX3d field_nT;     ///< vector sensor B (N x 3)
  Eigen::VectorXd total_nT;      ///< |B|
  Eigen::MatrixX3d direction;    ///< B / |B|, unit direction cosines
  Eigen::MatrixX3d delta_nT;     ///< central difference of B per sample (one-sided at the ends)
  double bt_scale_nT = 50000.0;  ///< scale of the induced and eddy columns (MagNav.jl: 50000)
  double dt_s = 0.1;             ///< sample period
};

/// Builds TermInputs from the columns `<vector>_x/_y/_z` of `data`.
TermInputs make_term_inputs(const FlightData& data, const std::string& vector_sensor,
                            double bt_scale_nT);

/// Central difference per sample (one-sided at both ends), as MagNav.jl's fdm; NOT divided by dt.
Eigen::VectorXd central_difference(const Eigen::VectorXd& x);

/// One physical effect. A term's spec is the exact string `--term`, the model YAML and diagnose
/// use.
class Term {
 public:
  virtual ~Term() = default;
  /// The spec (`induced5`, `current:cur_strb`, ...).
  virtual std::string spec() const = 0;
  /// Its physics in words, for tables and reports.
  virtual std::string effect() const = 0;
  /// Names of its columns, `<spec>.<suffix>`; their count is the number of coefficients.
  virtual std::vector<std::string> column_names() const = 0;
  /// Flight fields the term needs beyond the vector sensor (e.g. a current channel).
  virtual std::vector<std::string> required_fields() const { return {}; }
  /// False for terms a band-pass fit cannot see (a constant bias): they are fitted only against
  /// a reference.
  virtual bool bandpass_observable() const { return true; }
  /// Time by which this term says the scalar sensor is late relative to the vector sensor, s.
  /// The model realigns the scalar by this much before fitting and compensating.
  virtual double scalar_lag_s() const { return 0.0; }
  /// Samples on either side of a row that the row's columns depend on (0: the row alone, 1: a
  /// central difference), or -1 when they depend on the whole history (causal filters): a model
  /// whose terms all have a reach can be built on a slice of rows with that margin and give the
  /// same numbers.
  virtual int row_reach() const { return -1; }
  /// Writes N x column_names().size() regressor columns (scalar-field nT per unit coefficient).
  virtual void build(const TermInputs& in, Eigen::Ref<Eigen::MatrixXd> out) const = 0;

  /// column_names().size() and required_fields(), computed once (per-sample callers build the
  /// design matrix thousands of times a second; the names are strings).
  Eigen::Index columns() const {
    cache();
    return columns_;
  }
  const std::vector<std::string>& fields() const {
    cache();
    return fields_;
  }

 private:
  void cache() const {
    std::call_once(cache_once_, [this] {
      columns_ = static_cast<Eigen::Index>(column_names().size());
      fields_ = required_fields();
    });
  }
  mutable std::once_flag cache_once_;
  mutable Eigen::Index columns_ = 0;
  mutable std::vector<std::string> fields_;
};

/// A term shared read-only between the models and designs that use it (terms are immutable).
using TermPtr = std::shared_ptr<const Term>;

/// Parses a term spec. Known: permanent, induced, induced5, induced3, eddy, eddy8, eddy3, fdm,
/// bias, second_order, norm, lag:<seconds>, and the term language (terms_expr.h): field:, induced:,
/// scalar:<signal> with the shorthands current:, dcurrent:, rate:<channel>. Throws
/// magcomp::Error naming the spec otherwise.
std::unique_ptr<Term> make_term(const std::string& spec);

}  // namespace magcomp
