// magcomp: the steps of a round of diagnose_loop that revisit the kept terms (loop_round.h): the
// kept terms' parameters estimated again, a product's idle factor dropped, and the exchange of a
// term chosen before the others were written. A kept term giving way to a look-alike is in
// loop_look_alikes.cpp; a kept term leaving, in loop_redundant.cpp.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <optional>
#include <set>

#include "loop_round.h"
#include "magcomp/core/error.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/fit/parameter_fit.h"
#include "magcomp/core/io/channel_kinds.h"
#include "magcomp/core/model/terms_expr.h"

namespace magcomp::loop_steps {

bool Round::exchange(const DiagnoseOptions& options, std::set<std::string>* taken_out) {
  const LoopRound now = r_->rounds.back();
  const std::vector<std::string>& laws = r_->model.black_box_terms;
  // The round that added each term last, and the last round that changed the model (added
  // terms, wrote TL as the exact norm or chose the ridge strength): a term added in that round
  // was chosen with the model as it is, and its diagnosis would be the same. A term chosen
  // before the norm was written was chosen beside TL's other form: a look-alike it beat there
  // can beat it now.
  std::map<std::string, size_t> added_in;
  size_t last_adding = 0;
  for (size_t k = 1; k < r_->rounds.size(); ++k) {
    const LoopRound& lr = r_->rounds[k];
    if (lr.added.empty()) continue;
    last_adding = k;
    if (lr.regularisation || !lr.model_change.empty()) continue;
    for (const std::string& t : step_terms(lr.added)) added_in[t] = k;
  }
  for (const TermSpec& t : r_->model.terms) {
    const auto in = added_in.find(t.text());
    // A term of recorded channels, or a signal of the Earth's field alone (an eddy decay of B,
    // which the rates of the attitude drive): either may have stood in for effects the later
    // rounds wrote. Not the lag, which every term reads through.
    if (!removable(c_.start, t) || (fields_of(t).empty() && !t.expr()) ||
        taken_out->count(t.text()) || std::find(laws.begin(), laws.end(), t.text()) != laws.end() ||
        in == added_in.end() || in->second >= last_adding)
      continue;
    const auto [without, without_lr] = fit_score(without_term(r_->model, t));
    std::vector<Diagnosis> dxs;
    for (const FlightData* f : c_.flights) dxs.push_back(diagnose(without, *f, c_.truth, options));
    const std::vector<Eligible> eligible =
        eligible_candidates(dxs, c_.min_share, !c_.options.refuse_within_span_terms);
    std::optional<std::pair<Model, LoopRound>> best;
    const Eligible* best_e = nullptr;
    for (size_t k = 0, tried = 0; k < eligible.size() && tried < kTriesPerRound; ++k) {
      if (eligible[k].term.text() == t.text()) continue;
      ++tried;
      try {
        Model m = without;
        add_candidate_term(eligible[k].term, eligible[k].slow, c_.truth, &m);
        auto fitted = fit_score(std::move(m));
        const LoopRound& lr = fitted.second;
        if (!improves_on(lr, now)) continue;
        if (best && !(lr.heldout_std_nT < best->second.heldout_std_nT)) continue;
        best.emplace(std::move(fitted));
        best_e = &eligible[k];
      } catch (const Error&) {
      }
    }
    if (!best) continue;
    LoopRound lr = std::move(best->second);
    lr.round = round_;
    lr.added = best_e->term.text();
    lr.explained = best_e->explained;
    char why[300];
    std::snprintf(why, sizeof(why),
                  "the model without it, diagnosed again, takes %s: held-out error %.4f -> %.4f "
                  "nT (without either %.4f)",
                  lr.added.c_str(), now.heldout_std_nT, lr.heldout_std_nT,
                  without_lr.heldout_std_nT);
    lr.replaced.emplace_back(t.text(), why);
    taken_out->insert(t.text());
    keep(std::move(best->first), std::move(lr));
    return true;
  }
  return false;
}

namespace {

// The spec of `e` without its source k (the shorthand current:X for a plain current's field).
std::string without_source(const ExprTerm& e, size_t k) {
  SignalExpr signal = e.signal();
  signal.sources.erase(signal.sources.begin() + static_cast<std::ptrdiff_t>(k));
  if (e.projection() == Projection::Field && signal.sources.size() == 1 &&
      signal.transforms.empty() && is_electrical(signal.sources.front()))
    return "current:" + signal.sources.front();
  const char* projection = e.projection() == Projection::Field     ? "field:"
                           : e.projection() == Projection::Induced ? "induced:"
                                                                   : "scalar:";
  return projection + signal.str();
}

// Whether b is term a written again with other step thresholds: the same shape, and every
// parameter but the steps' thresholds the same.
bool differs_in_thresholds_only(const TermSpec& a, const TermSpec& b) {
  const ExprTerm* x = a.expr();
  const ExprTerm* y = b.expr();
  if (!x || !y || x->shape() != y->shape() || a.text() == b.text()) return false;
  const auto& tx = x->signal().transforms;
  const auto& ty = y->signal().transforms;
  if (tx.size() != ty.size()) return false;
  for (size_t k = 0; k < tx.size(); ++k)
    if (tx[k].kind != TransformKind::Step && tx[k].param != ty[k].param) return false;
  return true;
}

}  // namespace

Model with_term_as(const Model& model, const std::string& old_text, const std::string& spec) {
  Model m = model;
  if (spec.rfind("lag:", 0) == 0)  // one lag per model (Model::add_term)
    m.terms.erase(std::remove_if(m.terms.begin(), m.terms.end(),
                                 [&](const TermSpec& t) {
                                   return t.text() != old_text && t.text().rfind("lag:", 0) == 0;
                                 }),
                  m.terms.end());
  for (TermSpec& x : m.terms)
    if (x.text() == old_text) x = TermSpec(spec);
  for (std::string& x : m.slow_terms)
    if (x == old_text) x = TermSpec(spec).text();
  m.coefficients.resize(0);
  return m;
}

std::string other_projection(const TermSpec& t) {
  if (!t.expr()) return "";
  const std::string& text = t.text();
  for (const auto& [from, to] : {std::pair<std::string, std::string>{"scalar:", "field:"},
                                 std::pair<std::string, std::string>{"field:", "scalar:"}})
    if (text.rfind(from, 0) == 0) return to + text.substr(from.size());
  return "";
}

std::string freed_parameters(const Model& model, size_t k, const Model& start) {
  const TermSpec& t = model.terms[k];
  const ExprTerm* e = t.expr();
  if (!e || !revisable(start, model, t) || fields_of(t).empty()) return "";
  const auto& transforms = e->signal().transforms;
  if (std::none_of(transforms.begin(), transforms.end(), [](const Transform& x) {
        return x.has_param() && x.kind != TransformKind::Ramp;
      }))
    return "";        // no parameter (an alias such as current:X is written without one)
  return e->shape();  // every parameter '?' (a ramp's knot stays)
}

bool Round::drop_idle_factors() {
  const LoopRound now = r_->rounds.back();
  const Model& model = r_->model;
  struct Best {
    std::pair<Model, LoopRound> fitted;
    std::string old_text, new_text;
    double without_nT;
  };
  std::optional<Best> best;
  for (const TermSpec& t : model.terms) {
    const ExprTerm* e = t.expr();
    // A product of recorded channels only (not B or Bt), added by the loop, not a law's hinge
    // nor a slow term (its stage and lines are sized for the term as it is).
    if (!e || !revisable(c_.start, model, t) || e->signal().sources.size() < 2 ||
        fields_of(t).size() != e->signal().sources.size())
      continue;
    std::optional<std::pair<Model, LoopRound>> without;
    for (size_t k = 0; k < e->signal().sources.size(); ++k) {
      const std::string simpler = without_source(*e, k);
      if (std::any_of(model.terms.begin(), model.terms.end(),
                      [&](const TermSpec& x) { return x.text() == simpler; }))
        continue;
      try {
        if (!without) without.emplace(fit_score(without_term(model, t)));
        auto fitted = fit_score(with_term_as(model, t.text(), simpler));
        const LoopRound& lr = fitted.second;
        // The factor earns its place: the product beats the term without it.
        if (factor_resolved(now, lr)) continue;
        // The term without it is still a term: it passes a new term's checks against the model
        // without either.
        const LoopRound& none = without->second;
        if (!refusal(lr, none, c_.options).empty() ||
            !passes(lr.heldout_std_nT, none.heldout_std_nT))
          continue;
        if (best && !(lr.heldout_std_nT < best->fitted.second.heldout_std_nT)) continue;
        best.emplace(Best{std::move(fitted), t.text(), simpler, none.heldout_std_nT});
      } catch (const Error&) {
      }
    }
  }
  if (!best) return false;
  char why[300];
  std::snprintf(why, sizeof(why),
                "its factor earns no place: without it, held-out error %.4f -> %.4f nT (the model "
                "without either %.4f)",
                now.heldout_std_nT, best->fitted.second.heldout_std_nT, best->without_nT);
  replaced_as_round(std::move(best->fitted), best->old_text, best->new_text, why);
  return true;
}

void Round::replaced_as_round(std::pair<Model, LoopRound> fitted, const std::string& old_text,
                              const std::string& new_text, const std::string& why) {
  LoopRound lr = std::move(fitted.second);
  lr.round = round_;
  lr.added = new_text;
  // As the parameters estimated again: the variance share the change gains (negative: what a
  // simpler term costs, less than a term must gain).
  lr.explained = variance_share(lr.heldout_std_nT, r_->rounds.back().heldout_std_nT);
  lr.replaced.emplace_back(old_text, why);
  keep(std::move(fitted.first), std::move(lr));
}

bool Round::refine_parameters(const std::vector<Diagnosis>& dxs,
                              const std::set<std::string>& fixed) {
  const LoopRound now = r_->rounds.back();
  const Model& model = r_->model;
  // The kept terms whose parameters may be estimated again, and each one's freed spec.
  std::vector<std::pair<size_t, std::string>> freeable;
  for (size_t k = 0; k < model.terms.size(); ++k) {
    if (fixed.count(model.terms[k].text())) continue;
    const std::string freed = freed_parameters(model, k, c_.start);
    if (!freed.empty()) freeable.emplace_back(k, freed);
  }
  // The kept slow terms with one fixed low-pass, each with its time constant estimated again
  // (retimed_slow_term): (index, the spec with it).
  std::vector<std::pair<size_t, std::string>> retimed;
  for (size_t k = 0; k < model.terms.size(); ++k) {
    const TermSpec& t = model.terms[k];
    if (!removable(c_.start, t) || fixed.count(t.text()) ||
        std::find(model.slow_terms.begin(), model.slow_terms.end(), t.text()) ==
            model.slow_terms.end())
      continue;
    const std::string spec = retimed_slow_term(model, k);
    if (!spec.empty()) retimed.emplace_back(k, spec);
  }
  // The kept terms of a channel's signal written the other way (other_projection): a
  // body-fixed field projected on the Earth's field in place of a reading added to the scalar,
  // or the other way round. Minutes of calibration rows barely tell a slow term's two forms
  // apart, and a form a round kept may lose its lead once the fit changes (fit.lambda, a term
  // added). Judged as freed parameters are, with the resolution: a small gain there would take
  // the round in which an exchange of the term gains more.
  std::vector<std::pair<size_t, std::string>> reprojected;
  for (size_t k = 0; k < model.terms.size(); ++k) {
    const TermSpec& t = model.terms[k];
    if (fixed.count(t.text()) || !removable(c_.start, t) || fields_of(t).empty() ||
        std::find(model.black_box_terms.begin(), model.black_box_terms.end(), t.text()) !=
            model.black_box_terms.end())
      continue;
    const std::string other = other_projection(t);
    if (!other.empty() &&
        std::find(model.terms.begin(), model.terms.end(), TermSpec(other)) == model.terms.end())
      reprojected.emplace_back(k, other);
  }
  // The kept band-pass terms of aircraft states whose low-pass lies below the band, each to be
  // sized by the slow stage in its place (slow_form_of).
  std::vector<size_t> to_slow;
  for (size_t k = 0; k < model.terms.size(); ++k)
    if (!fixed.count(model.terms[k].text()) &&
        slow_form_of(model, k, c_.start, c_.options.slow_terms_on_lines))
      to_slow.push_back(k);
  if (freeable.empty() && retimed.empty() && reprojected.empty() && to_slow.empty()) return false;
  // The best that passes, without a new term ([0]) and with one ([1]).
  struct Choice {
    std::optional<std::pair<Model, LoopRound>> fitted;
    std::vector<std::pair<std::string, std::string>> changed;  // (old, new) texts
    std::string added;                                         // the term added, or ""
    bool to_slow = false;     // the change moves a kept term to the slow stage
    bool threshold = false;   // the change places a kept step's threshold again
    bool projection = false;  // the change writes a kept term's other projection
  };
  Choice choice[2];
  // `in_place`: a slow term's time constant below the band estimated again on the calibration
  // rows, or a step's threshold placed again by the held-out lines, judged by improves_in_place
  // (neither adds a channel); otherwise by improves_on.
  // `slow_text`: kept term moved to the slow stage (its text unchanged), judged by
  // moves_to_slow_stage.
  const auto consider = [&](Model m, const std::string& added, bool in_place = false,
                            const std::string& slow_text = "", bool threshold = false,
                            bool projection = false) {
    try {
      auto fitted = fit_score(std::move(m));
      std::vector<std::pair<std::string, std::string>> changed;
      for (size_t k = 0; k < model.terms.size() && k < fitted.first.terms.size(); ++k)
        if (fitted.first.terms[k].text() != model.terms[k].text())
          changed.emplace_back(model.terms[k].text(), fitted.first.terms[k].text());
      if (!slow_text.empty()) changed.emplace_back(slow_text, slow_text);
      if (changed.empty()) return;  // the same parameters: nothing new to judge
      const LoopRound& lr = fitted.second;
      // A reference fit's term moved to the lines: judged as a freed parameter is (the
      // calibration rows, which sized it unfiltered already, cannot fall).
      if (!slow_text.empty()
              ? (model.fit.method == FitMethod::kReference ? !improves_on(lr, now)
                                                           : !moves_to_slow_stage(lr, now))
          : in_place ? !improves_in_place(lr, now)
                     : !improves_on(lr, now))
        return;
      // A new term with them: the gain a candidate needs on each half.
      if (!added.empty() && !(passes(lr.selection_std_nT, now.selection_std_nT) &&
                              passes(lr.confirmation_std_nT, now.confirmation_std_nT)))
        return;
      Choice& c = choice[added.empty() ? 0 : 1];
      if (c.fitted && !(lr.heldout_std_nT < c.fitted->second.heldout_std_nT)) return;
      c.fitted.emplace(std::move(fitted));
      c.changed = std::move(changed);
      c.added = added;
      c.to_slow = !slow_text.empty();
      c.threshold = threshold;
      c.projection = projection;
    } catch (const Error&) {
    }
  };
  // Each term's parameters alone, with every other term in place.
  for (const auto& [k, freed] : freeable) {
    Model m = model;
    m.terms[k] = TermSpec(freed);
    consider(std::move(m), "");
  }
  for (const auto& [k, spec] : retimed)
    consider(with_term_as(model, model.terms[k].text(), spec), "",
             low_pass_below_band(model.terms[k], model.fit.band_low_hz));
  for (const auto& [k, spec] : reprojected)
    consider(with_term_as(model, model.terms[k].text(), spec), "", false, "", false, true);
  // Each kept step's threshold placed again where the held-out lines cross it: the model
  // without the step, diagnosed again with DiagnoseOptions::thresholds_on_selection, ranks the
  // same switch with the threshold its selection lines pin within what the calibration rows
  // cannot tell apart (DiagnoseOptions::place_thresholds_again). The fit rows alone, above,
  // place it where the calibration segments happen to cross it.
  if (c_.options.place_thresholds_again) {
    DiagnoseOptions options = c_.options;
    options.explainable_share = false;
    options.thresholds_on_selection = true;
    for (const auto& [k, freed] : freeable) {
      const TermSpec& kept = model.terms[k];
      const auto& transforms = kept.expr()->signal().transforms;
      if (std::none_of(transforms.begin(), transforms.end(),
                       [](const Transform& x) { return x.kind == TransformKind::Step; }))
        continue;
      try {
        const Model without = without_term(model, kept);
        std::optional<TermSpec> again;
        for (const FlightData* f : c_.flights) {
          const Diagnosis d = diagnose(without, *f, c_.truth, options);
          for (const Candidate& c : d.candidates)
            if (c.term.expr() && c.term.expr()->shape() == freed) {
              if (differs_in_thresholds_only(kept, c.term)) again = c.term;
              break;
            }
          if (again) break;
        }
        if (again) consider(with_term_as(model, kept.text(), again->text()), "", true, "", true);
      } catch (const Error&) {
      }
    }
  }
  for (size_t k : to_slow) {
    Model m = model;
    m.slow_terms.push_back(model.terms[k].text());
    if (m.fit.reference.empty()) m.fit.reference = c_.truth;
    if (m.fit.method == FitMethod::kReference && m.fit.slow_lines.empty())
      m.fit.slow_lines = lines_beside_calibration(m.fit, c_.flights);
    if (m.fit.method == FitMethod::kReference && m.fit.slow_lines.empty()) continue;
    consider(std::move(m), "", false, model.terms[k].text());
  }
  // The diagnosis's first candidates (of distinct channels, whatever their share alone), each
  // added with every kept term's parameters free: an effect whose signature a kept term took in
  // part (a flex's time constant stretched over a scalar lag) is written where neither the new
  // term alone nor the kept term's new parameters alone lowers the error.
  std::set<std::string> tried_channels;
  size_t tries = 0;
  for (const Diagnosis& d : dxs) {
    for (const Candidate& c : d.candidates) {
      if (tries >= kTriesPerRound) break;
      if (c_.options.refuse_within_span_terms && within_model_span(c.base_span_share)) continue;
      if (std::find(model.terms.begin(), model.terms.end(), c.term) != model.terms.end()) continue;
      const std::set<std::string> f = fields_of(c.term);
      std::string key;
      for (const std::string& x : f) key += x + ",";
      if (!f.empty() && !tried_channels.insert(key).second) continue;
      ++tries;
      Model m = model;
      try {
        add_candidate_term(c.term, c.slow, c_.truth, &m);
      } catch (const Error&) {
        continue;
      }
      if (m.terms.size() != model.terms.size() + 1) continue;  // it replaced a kept term
      for (const auto& [k, freed] : freeable) m.terms[k] = TermSpec(freed);
      consider(std::move(m), c.term.text());
    }
  }
  // A new term must earn its place over the parameters estimated again without it: the
  // accepted share and the resolution.
  Choice* pick = choice[0].fitted ? &choice[0] : choice[1].fitted ? &choice[1] : nullptr;
  if (pick == &choice[0] && choice[1].fitted &&
      passes(choice[1].fitted->second.heldout_std_nT, choice[0].fitted->second.heldout_std_nT))
    pick = &choice[1];
  if (!pick) return false;
  auto& best = pick->fitted;
  const std::string& best_new = pick->added;
  const auto& best_changed = pick->changed;
  LoopRound lr = std::move(best->second);
  lr.round = round_;
  lr.added = best_new;
  for (const auto& [from, to] : best_changed) lr.added += (lr.added.empty() ? "" : " + ") + to;
  lr.explained = variance_share(lr.heldout_std_nT, now.heldout_std_nT);
  for (const auto& [from, to] : best_changed) {
    char why[400];
    if (pick->to_slow && model.fit.method == FitMethod::kReference)
      std::snprintf(why, sizeof(why),
                    "sized by the slow stage on the calibration rows and the lines beside them "
                    "(fit.slow_lines, cross-fitted where scored) in place of the calibration rows "
                    "alone, whose minutes barely move it: held-out error %.4f -> %.4f nT",
                    now.heldout_std_nT, lr.heldout_std_nT);
    else if (pick->to_slow)
      std::snprintf(why, sizeof(why),
                    "sized by the slow stage (the calibration rows, unfiltered) in place of the "
                    "band-pass, which passes little of its low-pass: calibration rows %.4f -> "
                    "%.4f nT, held-out error %.4f -> %.4f nT",
                    now.calibration_std_nT, lr.calibration_std_nT, now.heldout_std_nT,
                    lr.heldout_std_nT);
    else if (pick->projection)
      std::snprintf(why, sizeof(why),
                    "written as %s, with every other term in place: held-out error %.4f -> "
                    "%.4f nT",
                    to.rfind("field:", 0) == 0 ? "a body-fixed field projected on the Earth's field"
                                               : "a reading added to the scalar",
                    now.heldout_std_nT, lr.heldout_std_nT);
    else if (pick->threshold)
      std::snprintf(why, sizeof(why),
                    "its threshold placed again where the held-out lines cross it (the model "
                    "without it, diagnosed again, ranks %s): held-out error %.4f -> %.4f nT",
                    to.c_str(), now.heldout_std_nT, lr.heldout_std_nT);
    else
      std::snprintf(why, sizeof(why),
                    "its parameters estimated again with every other term in place%s%s: held-out "
                    "error %.4f -> %.4f nT",
                    best_new.empty() ? "" : " and ", best_new.c_str(), now.heldout_std_nT,
                    lr.heldout_std_nT);
    lr.replaced.emplace_back(from, why);
  }
  keep(std::move(best->first), std::move(lr));
  return true;
}

}  // namespace magcomp::loop_steps
