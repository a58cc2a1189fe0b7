// magcomp: a term parsed once (term_spec.h).
#include "magcomp/core/model/term_spec.h"

#include "magcomp/core/error.h"
#include "magcomp/core/model/terms_expr.h"

namespace magcomp {

TermSpec::TermSpec(const std::string& text) : text_(text), term_(make_term(text)) {}

TermSpec::TermSpec(const char* text) : TermSpec(std::string(text)) {}

TermSpec::TermSpec(TermPtr term) : text_(term ? term->spec() : ""), term_(std::move(term)) {}

const Term& TermSpec::term() const {
  if (!term_) throw Error("an empty term was used where a term is needed");
  return *term_;
}

const ExprTerm* TermSpec::expr() const { return dynamic_cast<const ExprTerm*>(term_.get()); }

}  // namespace magcomp
