// magcomp: a term as a model holds it: parsed once, when the model is loaded or the term is
// given (the term language's tree, terms_expr.h, or a fixed term such as `induced`), and
// written as its text only at the edges (the model file, the CLI, tables and JSON).
#pragma once

#include <memory>
#include <ostream>
#include <string>

#include "magcomp/core/model/term.h"

namespace magcomp {

class ExprTerm;

class TermSpec {
 public:
  /// No term: text "", empty() true (a candidate not yet filled, a partner that is none).
  TermSpec() = default;
  /// Parses `text` (make_term); throws magcomp::Error naming it when it is not a term. The text
  /// is kept as given (models write their terms canonically: Model::add_term).
  TermSpec(const std::string& text);  // NOLINT: a spec is written where a term is expected
  TermSpec(const char* text);         // NOLINT
  /// A term parsed from text (shared, not copied; its parameters are what its spec writes),
  /// written as its canonical spec (Term::spec).
  explicit TermSpec(TermPtr term);
  /// True for the default TermSpec (no term).
  bool empty() const { return !term_; }
  /// The spec as written.
  const std::string& text() const { return text_; }
  operator const std::string&() const { return text_; }  // NOLINT: the text at the edges
  /// The parsed term; throws magcomp::Error for an empty TermSpec.
  const Term& term() const;
  const TermPtr& shared() const { return term_; }
  /// The term of the language (field:, induced:, scalar: and their shorthands), or nullptr for a
  /// fixed term (permanent, induced, eddy, lag:, ...) or an empty TermSpec.
  const ExprTerm* expr() const;

  friend bool operator==(const TermSpec& a, const TermSpec& b) { return a.text_ == b.text_; }
  friend bool operator!=(const TermSpec& a, const TermSpec& b) { return a.text_ != b.text_; }
  friend bool operator==(const TermSpec& a, const std::string& b) { return a.text_ == b; }
  friend bool operator==(const std::string& a, const TermSpec& b) { return a == b.text_; }
  friend bool operator!=(const TermSpec& a, const std::string& b) { return a.text_ != b; }
  friend bool operator!=(const std::string& a, const TermSpec& b) { return a != b.text_; }
  friend bool operator==(const TermSpec& a, const char* b) { return a.text_ == b; }
  friend bool operator!=(const TermSpec& a, const char* b) { return a.text_ != b; }
  friend bool operator<(const TermSpec& a, const TermSpec& b) { return a.text_ < b.text_; }
  friend std::ostream& operator<<(std::ostream& o, const TermSpec& t) { return o << t.text_; }

 private:
  std::string text_;
  TermPtr term_;
};

}  // namespace magcomp
