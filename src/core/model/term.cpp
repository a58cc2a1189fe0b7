// magcomp: term inputs, the factory and the catalogue.
#include "magcomp/core/model/term.h"

#include <cmath>
#include <cstdlib>

#include "magcomp/core/error.h"
#include "magcomp/core/model/terms_expr.h"
#include "magcomp/core/model/terms_physical.h"
#include "magcomp/core/model/terms_tl.h"

namespace magcomp {

Eigen::VectorXd central_difference(const Eigen::VectorXd& x) {
  const Eigen::Index n = x.size();
  Eigen::VectorXd d = Eigen::VectorXd::Zero(n);
  if (n < 2) return d;
  d[0] = x[1] - x[0];
  d[n - 1] = x[n - 1] - x[n - 2];
  for (Eigen::Index i = 1; i + 1 < n; ++i) d[i] = 0.5 * (x[i + 1] - x[i - 1]);
  return d;
}

TermInputs make_term_inputs(const FlightData& data, const std::string& vector_sensor,
                            double bt_scale_nT) {
  TermInputs in;
  in.data = &data;
  in.bt_scale_nT = bt_scale_nT;
  in.dt_s = data.size() > 1 ? data.dt_s() : 0.1;
  const Eigen::Index n = data.size();
  in.field_nT.resize(n, 3);
  in.field_nT.col(0) = data.column(vector_sensor + "_x");
  in.field_nT.col(1) = data.column(vector_sensor + "_y");
  in.field_nT.col(2) = data.column(vector_sensor + "_z");
  in.total_nT = in.field_nT.rowwise().norm();
  in.direction = in.field_nT.array().colwise() / in.total_nT.array();
  in.delta_nT.resize(n, 3);
  for (int c = 0; c < 3; ++c) in.delta_nT.col(c) = central_difference(in.field_nT.col(c));
  return in;
}

std::unique_ptr<Term> make_term(const std::string& spec) {
  const auto colon = spec.find(':');
  const std::string kind = spec.substr(0, colon);
  const std::string arg = colon == std::string::npos ? "" : spec.substr(colon + 1);
  if (colon == std::string::npos) {
    if (kind == "permanent") return std::make_unique<PermanentTerm>();
    if (kind == "induced") return std::make_unique<InducedTerm>(6);
    if (kind == "induced5") return std::make_unique<InducedTerm>(5);
    if (kind == "induced3") return std::make_unique<InducedTerm>(3);
    if (kind == "eddy") return std::make_unique<EddyTerm>(9);
    if (kind == "eddy8") return std::make_unique<EddyTerm>(8);
    if (kind == "eddy3") return std::make_unique<EddyTerm>(3);
    if (kind == "fdm") return std::make_unique<FdmTerm>();
    if (kind == "bias") return std::make_unique<BiasTerm>();
    if (kind == "second_order") return std::make_unique<SecondOrderTerm>();
    if (kind == "norm") return std::make_unique<NormTerm>();
  } else {
    if (auto t = parse_expr_term(spec)) return t;
    if (kind == "lag") {
      char* end = nullptr;
      const double lag_s = std::strtod(arg.c_str(), &end);
      if (end && *end == '\0' && std::isfinite(lag_s) && std::abs(lag_s) <= 10.0) {
        return std::make_unique<LagTerm>(lag_s);
      }
      throw Error("term '" + spec + "': lag needs seconds in [-10, 10], e.g. lag:0.3");
    }
  }
  throw Error("term '" + spec +
              "': unknown (known: permanent, induced, induced5, induced3, eddy, " +
              "eddy8, eddy3, fdm, bias, second_order, norm, lag:<seconds>, current:<channel>, " +
              "dcurrent:<channel>, rate:<channel>, and field:|induced:|scalar:<signal>)");
}

}  // namespace magcomp
