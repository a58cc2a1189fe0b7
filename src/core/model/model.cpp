// magcomp: the model's terms and columns, its lag and the realigned scalar, adding terms (see
// model.h).
#include <algorithm>
#include <string>
#include <vector>

#include "magcomp/core/error.h"
#include "magcomp/core/math/timeseries.h"
#include "magcomp/core/model/model.h"
#include "magcomp/core/model/terms_expr.h"

namespace magcomp {

std::vector<TermPtr> Model::make_terms() const {
  std::vector<TermPtr> out;
  out.reserve(terms.size());
  for (const TermSpec& t : terms) out.push_back(t.shared());
  return out;
}

std::vector<std::string> Model::make_column_names() const {
  std::vector<std::string> names;
  for (const auto& t : make_terms()) {
    for (const auto& c : t->column_names()) names.push_back(c);
  }
  return names;
}

double Model::scalar_lag_s() const {
  double lag = 0.0;
  for (const auto& t : make_terms()) lag += t->scalar_lag_s();
  return lag;
}

Eigen::VectorXd aligned_scalar(const Model& model, const FlightData& data) {
  return aligned_scalar(model, data, model.scalar_lag_s());
}

Eigen::VectorXd aligned_scalar(const Model& model, const FlightData& data, double lag) {
  const auto s = data.column(model.scalar);
  if (lag == 0.0) return s;
  return shift_samples(s, -lag / data.dt_s());
}

namespace {
// The term written canonically (Term::spec), with the tree of that text: a spec may round a
// parameter given with more digits, and a model holds what its file will say. A term already
// written so is kept as parsed.
TermSpec canonical_of(const TermSpec& term) {
  std::string text = term.term().spec();
  return text == term.text() ? term : TermSpec(text);
}
}  // namespace

bool Model::add_term(const TermSpec& term) {
  const TermSpec canonical = canonical_of(term);
  if (std::find(terms.begin(), terms.end(), canonical) != terms.end()) return false;
  if (const ExprTerm* e = canonical.expr()) {
    for (auto& t : terms) {
      const ExprTerm* old = t.expr();
      if (old && old->shape() == e->shape() && old->spec().find('(') != std::string::npos) {
        for (auto* list : {&slow_terms, &black_box_terms}) {  // they name it by its spec
          std::replace(list->begin(), list->end(), t.text(), canonical.text());
        }
        t = canonical;  // the same expression with new parameter values
        coefficients.resize(0);
        return true;
      }
    }
  }
  if (canonical.text().rfind("lag:", 0) == 0) {  // one lag per model: a new one replaces the old
    terms.erase(std::remove_if(terms.begin(), terms.end(),
                               [](const TermSpec& t) { return t.text().rfind("lag:", 0) == 0; }),
                terms.end());
  }
  terms.push_back(canonical);
  return true;
}

void require_slow_term(const TermSpec& term) {
  if (const ExprTerm* e = term.expr(); e && e->signal().has_free())
    throw Error("'" + term.text() + "' has a free parameter (?): give its value");
}

void Model::add_slow_term(const TermSpec& term, const std::string& reference) {
  const TermSpec canonical = canonical_of(term);
  require_slow_term(canonical);
  add_term(canonical);
  if (std::find(slow_terms.begin(), slow_terms.end(), canonical) == slow_terms.end())
    slow_terms.push_back(canonical);
  if (fit.reference.empty()) fit.reference = reference;
}

std::vector<Eigen::Index> fittable_columns(FitMethod method, const std::vector<TermPtr>& terms) {
  const bool bandpass = method == FitMethod::kBandpass;
  std::vector<Eigen::Index> out;
  Eigen::Index c = 0;
  for (const auto& t : terms) {
    for (Eigen::Index k = 0; k < t->columns(); ++k, ++c) {
      if (!bandpass || t->bandpass_observable()) out.push_back(c);
    }
  }
  return out;
}

namespace {
// Per column of `terms`: whether its term is one of `slow_terms`.
std::vector<bool> slow_mask(const std::vector<TermPtr>& terms,
                            const std::vector<std::string>& slow_terms) {
  std::vector<bool> out;
  for (const auto& t : terms) {
    const bool slow =
        std::find(slow_terms.begin(), slow_terms.end(), t->spec()) != slow_terms.end();
    out.insert(out.end(), static_cast<size_t>(t->columns()), slow);
  }
  return out;
}
}  // namespace

std::vector<Eigen::Index> fittable_columns(FitMethod method, const std::vector<TermPtr>& terms,
                                           const std::vector<std::string>& slow_terms) {
  std::vector<Eigen::Index> out = fittable_columns(method, terms);
  if (slow_terms.empty()) return out;
  const std::vector<bool> slow = slow_mask(terms, slow_terms);
  out.erase(std::remove_if(out.begin(), out.end(),
                           [&](Eigen::Index c) { return slow[static_cast<size_t>(c)]; }),
            out.end());
  return out;
}

std::vector<Eigen::Index> slow_columns(const std::vector<TermPtr>& terms,
                                       const std::vector<std::string>& slow_terms) {
  std::vector<Eigen::Index> out;
  if (slow_terms.empty()) return out;
  const std::vector<bool> slow = slow_mask(terms, slow_terms);
  for (size_t c = 0; c < slow.size(); ++c) {
    if (slow[c]) out.push_back(static_cast<Eigen::Index>(c));
  }
  return out;
}

const char* fit_method_name(FitMethod m) {
  return m == FitMethod::kReference ? "reference" : "bandpass";
}

}  // namespace magcomp
