// magcomp: diagnose_loop's step for a channel's field whose size follows a state of the aircraft
// (Round::size_following_a_state, loop_round.h).
#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "line_means.h"
#include "loop_round.h"
#include "magcomp/core/error.h"
#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/io/channel_kinds.h"
#include "magcomp/core/model/term.h"

namespace magcomp::loop_steps {

namespace {

using diagnose_search::remove_line_means;

// One flight's held-out rows for the screen: the model's error (nT) and the field's direction
// in the sensor frame, each held-out line's rows contiguous in `rows`.
struct ScreenRows {
  std::vector<Eigen::Index> rows;
  std::vector<Eigen::Index> line_start;  // the first index into `rows` of each line's piece
  Eigen::VectorXd error_nT;              // on `rows`, each line's mean removed
  Eigen::MatrixX3d direction;            // on `rows`
};

// A channel on the screen's rows, standardised over them; empty when it has gaps or is steady.
Eigen::VectorXd standardised(const FlightData& data, const std::string& channel,
                             const ScreenRows& s) {
  const FlightData::Column v = data.column(channel);
  Eigen::VectorXd out(static_cast<Eigen::Index>(s.rows.size()));
  for (size_t r = 0; r < s.rows.size(); ++r) out[static_cast<Eigen::Index>(r)] = v[s.rows[r]];
  if (!out.allFinite()) return {};
  out.array() -= out.mean();
  const double sd = std::sqrt(out.squaredNorm() / static_cast<double>(out.size()));
  if (!(sd > 0)) return {};
  return out / sd;
}

}  // namespace

bool Round::size_following_a_state() {
  const Model& model = r_->model;
  // The pair is sized where the state moves: only with slow terms sized on the lines too (the
  // loop's round that sizes them there, or a model that lists fit.slow_lines). On calibration
  // rows that hold the state steady, the two terms are one column, and their sizes there are
  // the ridge's.
  if (model.fit.slow_lines.empty()) return false;
  std::set<std::string> in_model;
  for (const std::string& t : model.terms)
    for (const std::string& f : fields_of(TermSpec(t))) in_model.insert(f);
  // The screen's channels: electrical channels (whose field a wire or a load makes) and the
  // aircraft's other recorded states (flaps, temperatures, engine speed, switches), none a term
  // of the model already reads.
  std::vector<std::string> loads, states;
  for (const std::string& n : c_.flights.front()->names()) {
    if (in_model.count(n) || !is_aircraft_state(n)) continue;
    bool everywhere = true;
    for (const FlightData* f : c_.flights) everywhere = everywhere && f->has(n);
    if (!everywhere) continue;
    (is_electrical(n) ? loads : states).push_back(n);
  }
  if (loads.empty() || states.empty()) return false;
  // Per pair (load, state): the Gram of the six columns [x d, x s d] over every flight's held-out
  // rows (x the load, s the state, d the field's direction, each standardised, each line's mean
  // removed), and their products with the error.
  const size_t pairs = loads.size() * states.size();
  std::vector<Eigen::Matrix<double, 6, 6>> gram(pairs, Eigen::Matrix<double, 6, 6>::Zero());
  std::vector<Eigen::Matrix<double, 6, 1>> xe(pairs, Eigen::Matrix<double, 6, 1>::Zero());
  double ee = 0;
  for (size_t f = 0; f < c_.flights.size(); ++f) {
    const FlightData& data = *c_.flights[f];
    const HeldOut& ho = c_.held_out[f];
    const Evaluation ev = evaluate_model(model, data, c_.truth, false);
    const TermInputs inputs = make_term_inputs(data, model.vector, model.bt_scale_nT);
    ScreenRows s;
    double last_line = NAN;
    for (Eigen::Index i = 0; i < ev.error_nT.size(); ++i) {
      // Held out, with an error and a field direction (a gap of the vector sensor: not screened).
      if (static_cast<size_t>(i) >= ho.fold.size() || ho.fold[static_cast<size_t>(i)] < 0 ||
          !std::isfinite(ev.error_nT[i]) || !inputs.direction.row(i).allFinite())
        continue;
      const double line = i < ho.line.size() ? ho.line[i] : 0.0;
      if (s.rows.empty() || line != last_line)
        s.line_start.push_back(static_cast<Eigen::Index>(s.rows.size()));
      last_line = line;
      s.rows.push_back(i);
    }
    const auto m = static_cast<Eigen::Index>(s.rows.size());
    if (m < 100) continue;
    s.error_nT.resize(m);
    s.direction.resize(m, 3);
    for (Eigen::Index r = 0; r < m; ++r) {
      s.error_nT[r] = ev.error_nT[s.rows[static_cast<size_t>(r)]];
      s.direction.row(r) = inputs.direction.row(s.rows[static_cast<size_t>(r)]);
    }
    remove_line_means(s.line_start, s.error_nT);
    ee += s.error_nT.squaredNorm();
    std::vector<Eigen::VectorXd> state_values;
    for (const std::string& n : states) state_values.push_back(standardised(data, n, s));
    Eigen::MatrixXd x(m, 6);
    for (size_t a = 0; a < loads.size(); ++a) {
      const Eigen::VectorXd load = standardised(data, loads[a], s);
      if (load.size() == 0) continue;
      for (size_t b = 0; b < states.size(); ++b) {
        if (state_values[b].size() == 0) continue;
        for (int k = 0; k < 3; ++k) {
          x.col(k) = load.cwiseProduct(s.direction.col(k));
          x.col(3 + k) = x.col(k).cwiseProduct(state_values[b]);
        }
        remove_line_means(s.line_start, x);
        gram[a * states.size() + b] += x.transpose() * x;
        xe[a * states.size() + b] += x.transpose() * s.error_nT;
      }
    }
  }
  if (!(ee > 0)) return false;
  // What the state's factor adds: the share of the pair's six columns beyond the better of its
  // two halves alone (the load's field, the product's).
  std::vector<std::pair<double, size_t>> gains;
  for (size_t p = 0; p < pairs; ++p) {
    if (gram[p].isZero()) continue;
    const auto explained = [&](const Eigen::MatrixXd& g, const Eigen::VectorXd& h) {
      const double v = diagnose_search::explained_share(g, h, ee);
      return std::isfinite(v) ? v : 0.0;
    };
    const double both = explained(gram[p], xe[p]);
    const double load_alone = explained(gram[p].topLeftCorner(3, 3), xe[p].head(3));
    const double product_alone = explained(gram[p].bottomRightCorner(3, 3), xe[p].tail(3));
    const double gain = both - std::max(load_alone, product_alone);
    if (both >= c_.options.accept_fraction && gain >= c_.options.accept_fraction)
      gains.emplace_back(gain, p);
  }
  std::sort(gains.begin(), gains.end(), [](const auto& a, const auto& b) { return a > b; });
  // The best pairs (kTriesPerRound at most), each fitted as slow terms (sized unfiltered against
  // the reference, where the band-pass sees the load's field at one size only when the state is
  // steady on the calibration rows): the best that passes a pair's checks is kept.
  std::optional<std::pair<Model, LoopRound>> best;
  std::vector<std::string> best_terms;
  std::vector<double> best_alone;
  for (size_t k = 0; k < gains.size() && k < kTriesPerRound; ++k) {
    const std::string& load = loads[gains[k].second / states.size()];
    const std::string& state = states[gains[k].second % states.size()];
    const std::vector<std::string> terms = {"current:" + load, "field:" + load + "*" + state};
    try {
      LoopRound alone[2];
      for (int t = 0; t < 2; ++t) {
        Model one = model;
        add_candidate_term(TermSpec(terms[static_cast<size_t>(t)]), true, c_.truth, &one);
        alone[t] = fit_score(std::move(one)).second;
      }
      Model both = model;
      for (const std::string& t : terms) add_candidate_term(TermSpec(t), true, c_.truth, &both);
      auto fitted = fit_score(std::move(both));
      if (!pair_passes(fitted.second, alone[0], alone[1])) {
        // The first check the pair fails, with its numbers.
        const LoopRound& lr = fitted.second;
        const LoopRound& now = r_->rounds.back();
        std::string why = refusal(lr, now, c_.options);
        char buf[300];
        if (why.empty() && !passes(lr.selection_std_nT, now.selection_std_nT)) {
          std::snprintf(buf, sizeof(buf), "%s would not fall enough (%.3f -> %.3f nT)",
                        half_name(*r_, c_.flights.size(), 0).c_str(), now.selection_std_nT,
                        lr.selection_std_nT);
          why = buf;
        } else if (why.empty() && !passes(lr.confirmation_std_nT, now.confirmation_std_nT)) {
          std::snprintf(buf, sizeof(buf), "%s would not fall enough (%.3f -> %.3f nT)",
                        half_name(*r_, c_.flights.size(), 1).c_str(), now.confirmation_std_nT,
                        lr.confirmation_std_nT);
          why = buf;
        } else if (why.empty()) {
          std::snprintf(buf, sizeof(buf),
                        "a term alone does about as well (held out %.3f nT together, %.3f and "
                        "%.3f nT alone)",
                        lr.heldout_std_nT, alone[0].heldout_std_nT, alone[1].heldout_std_nT);
          why = buf;
        }
        refuse(terms[0] + " + " + terms[1], "a size that follows " + state + ": " + why);
        continue;
      }
      if (!best || fitted.second.heldout_std_nT < best->second.heldout_std_nT) {
        best = std::move(fitted);
        best_terms = terms;
        best_alone = {alone[0].heldout_std_nT, alone[1].heldout_std_nT};
      }
    } catch (const Error&) {
    }
  }
  if (!best) return false;
  keep_together(std::move(*best), best_terms, best_alone);
  return true;
}

}  // namespace magcomp::loop_steps
