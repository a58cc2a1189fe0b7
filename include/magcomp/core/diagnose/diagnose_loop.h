// magcomp: the user's loop as one call: diagnose, add the accepted top term, refit, repeat.
#pragma once

#include <cmath>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "magcomp/core/diagnose/diagnose.h"

namespace magcomp {

/// What would tell a look-alike from a round's kept term: the recorded channel that the ratio of
/// their channels (kept / look-alike; a term of several channels: their product) follows over
/// the flights, such as a lateral acceleration over a yaw rate following the airspeed.
struct LookAlikeRatio {
  std::string term;           ///< the look-alike, as LoopRound::look_alikes names it
  std::string kept_channel;   ///< the kept term's channel (several: joined with "*")
  std::string alike_channel;  ///< the look-alike's channel (several: joined with "*")
  std::string channel;        ///< the channel their ratio follows
  double correlation = NAN;   ///< Pearson's r of the ratio with `channel`, dimensionless
  double relative_std = NAN;  ///< `channel`'s std / |mean| over the flights, dimensionless
};

/// One round of the loop (round 0: the model as given, refitted).
struct LoopRound {
  int round = 0;
  std::string added;            ///< the term added in this round ("" for round 0)
  double explained = 0.0;       ///< its conservative explained share (Candidate)
  double heldout_std_nT = 0.0;  ///< error std (line means removed) on the held-out lines
  /// The same on each half of them: the first diagnosis's selection and confirmation lines.
  double selection_std_nT = NAN, confirmation_std_nT = NAN;
  double all_std_nT = 0.0;  ///< the same on every line of the flight
  /// Error std on the model's calibration rows (fit.lines / fit.windows), unfiltered, each
  /// contiguous segment's mean removed, nT: what a term's size does where it was fitted, at
  /// every frequency the band-pass does not see.
  double calibration_std_nT = NAN;
  /// The model's terms that read a recorded channel of the aircraft (ExprTerm::required_fields:
  /// not TL's, not a lag, not a term of the field itself), as written.
  std::vector<std::string> channel_terms;
  double fom_nT = NAN;             ///< figure of merit on the model's calibration maneuvers
  double validation_std_nT = NAN;  ///< error std on the validation flight (NaN: none given)
  /// The round added a learned law (hinges of a channel, Model::black_box_terms), not a term of
  /// the language; `added` lists its terms joined by " + ".
  bool black_box = false;
  /// The terms tried in this round and refused, each with why (a term is kept only if it lowers
  /// the held-out error and, with a validation flight, the error there).
  std::vector<std::pair<std::string, std::string>> rejected;
  /// The round added terms together (`added` joins them by " + "): a set a diagnosis chose
  /// together (Diagnosis::joint), each of its terms needed and the set better than the first
  /// single term that passes by the accepted share; two terms of which one or both failed alone
  /// and each lowers the pair's error by the accepted share; or a lag ranked first with the
  /// channel term it was judged with (Candidate::partner), not eligible alone, whose pair lowers
  /// the error below the first single term that passes.
  bool together = false;
  /// The round's slow terms are sized on the held-out lines too (fit.slow_lines; each half's
  /// error scored with them sized on the other half's lines), taken because nothing passed with
  /// them sized on the calibration rows alone (DiagnoseOptions::slow_terms_on_lines).
  bool slow_on_lines = false;
  /// The held-out error std of each `together` term alone, nT (same order as `added`).
  std::vector<double> alone_std_nT;
  /// Terms of earlier rounds that this round's terms made redundant (the backward pass), and, in
  /// the last round, a kept drift one flight cannot tell from chance
  /// (DiagnoseOptions::chance_control), each with why; the round's scores are those of the
  /// model without them.
  std::vector<std::pair<std::string, std::string>> removed;
  /// The kept term this round's single term took the place of (DiagnoseOptions::exchange_terms),
  /// with why: the model without it, diagnosed again, ranks this term first and it lowers the
  /// held-out error. Empty for a round that only adds.
  std::vector<std::pair<std::string, std::string>> replaced;
  /// The held-out error std on each flight the loop learns from, nT (in the order given).
  std::vector<double> flight_heldout_std_nT;
  /// The held-out error's sum of squares on each held-out line (each line's mean removed), nT²:
  /// the flights in the order given, each flight's lines in ascending number.
  std::vector<double> line_ss_nT2;
  /// The ridge strength of this round's model (fit.lambda, dimensionless).
  double lambda = NAN;
  /// The round changed only the ridge strength (fit.lambda, chosen on the held-out lines;
  /// `added` reads "fit.lambda <value>"), before the round's terms; it shares their round number.
  bool regularisation = false;
  /// The round wrote TL as the exact norm (DiagnoseOptions::exact_norm; `added` lists the terms it
  /// added, `norm` and, with the fit against the reference, `bias`) and how the fit changed
  /// ("fit.method reference (mag_1_c), fit.lambda 1e-06"; "" when the fit stayed); it shares the
  /// round number of the round's terms. Empty otherwise.
  std::string model_change;
  /// The round's term was judged with the flights as the halves (DiagnoseOptions::across_flights:
  /// each flight's held-out lines scored with slow terms sized on the other flights' lines), and
  /// the rounds after it are judged so too; the previous round's model so scored, nT (held out,
  /// then each half). False and NaN otherwise.
  bool flight_halves = false;
  double flight_halves_before_nT[3] = {NAN, NAN, NAN};
  /// For a ridge step taken because the round's first term lay within the model's own span
  /// (DiagnoseOptions::ridge_for_span_terms): that term, and the share of its columns' energy the
  /// model's columns span (Candidate::base_span_share). Empty otherwise.
  std::string in_place_of;
  double in_place_of_span_share = NAN;
  /// Terms of other channels that, each in place of this round's single term, pass the same
  /// checks and leave a held-out error the kept term does not beat by the accepted share and
  /// the resolution: the flights cannot tell their channels from the kept one's. Each with its
  /// held-out error std, nT; empty when the kept term's channel is told apart (or for a step
  /// that is not a single term).
  std::vector<std::pair<std::string, double>> look_alikes;
  /// For look-alikes of this round's single term: the recorded channel the ratio of the kept
  /// term's channels to the look-alike's follows over the flights, which a flight where that
  /// channel varies more would tell them apart by (loop_steps::look_alike_ratio); only those
  /// whose ratio some channel follows.
  std::vector<LookAlikeRatio> look_alike_ratios;
  /// For this round's single term: the recorded states the flights hold so steady that the term
  /// times one of them (a product, such as a wire's current times a bus voltage held within a few
  /// percent) differs from it by less than the resolution on the held-out lines: the flights
  /// cannot tell whether the effect scales with one of them. Each with its relative std over the
  /// flights (std / |mean|, dimensionless), steadiest first; empty for a lag or a step that is
  /// not a single term (loop_steps::steady_factors).
  std::vector<std::pair<std::string, double>> steady_factors;
  /// For this round's single term of one recorded channel: the other channels of the products
  /// with that channel the round's diagnosis ranked as eligible and explaining at least as much
  /// as the term on both halves, where the search could not tell them apart from the term on the
  /// selection lines (Round::first_single; tried in place once every effect is written,
  /// Round::steady_factor_in_place). Not a key of the JSON.
  std::vector<std::string> paired_factors;
};

struct LoopResult {
  Model model;                    ///< the final model, fitted
  std::vector<LoopRound> rounds;  ///< round 0 first
  Diagnosis last;                 ///< the last diagnosis (the one that stopped the loop)
  /// Over several flights: the last round's diagnosis of each (`last` is the first's).
  std::vector<Diagnosis> last_flights;
  std::string stop_reason;
  /// Over several flights: each flight on which the model fitted on all of them leaves more than
  /// three times (plus the resolution) what it leaves fitted on that flight alone, in words.
  std::vector<std::string> warnings;
};

/// Runs diagnose -> add the top candidate if it is accepted and explains at least `min_share`
/// -> refit (model.fit, on `data`) -> repeat, at most `max_rounds` times. The error is measured
/// against `truth` on the lines held out by the first diagnosis. An accepted candidate is kept
/// only if the refitted model lowers the held-out error and, with a `validation` flight (another
/// flight of the same aircraft: same sensors and truth field), the error there; otherwise the next
/// accepted candidate is tried (up to three per round). When none passes (or none is accepted), a
/// learned law of the channel of one of the two first ranked candidates that helped on the
/// selection lines is tried under the same checks (hinges at the channel's quantiles through the
/// candidate's dynamic tail, marked in Model::black_box_terms and LoopRound::black_box); as its
/// hinges fit what is left by their freedom alone, it must also explain the accepted share of the
/// held-out variance for each of its hinges. The loop stops when that fails too. Before the learned
/// law, while the residual stays predictable, pairs of terms of the channels that predict the
/// residual (each one's plain and first ranked term) are tried together (effects that act together:
/// one or both fail alone), under the same checks plus two: the pair lowers the error on each half
/// of the held-out lines by the accepted share and the resolution, and each of its terms lowers the
/// pair's held-out error variance by the accepted share (DiagnoseOptions::joint_steps). After each
/// kept round, a backward pass drops an earlier term whose removal raises the held-out variance by
/// less than a quarter of the accepted share (and the validation error by no more), one at a time:
/// a term that later terms made redundant leaves, and the round lists it. So the final model is
/// never worse than the start on either. With DiagnoseOptions::choose_lambda (off by default),
/// before each round's terms the ridge strength fit.lambda is chosen on the held-out lines among
/// the start model's and 1/10, 1/100 and 1/1000 of it: the one with the lowest held-out error is
/// kept if that error falls by the accepted share and the resolution, falls on each half, and (with
/// a validation flight) falls there; the round is then diagnosed again. A ridge too strong for the
/// flight biases the fit, and a term that only undoes the bias would otherwise be taken for an
/// effect. It never exceeds the start model's: a stronger ridge hides an effect the model lacks
/// instead of writing it.
/// When no step passes, the kept terms' parameters are first estimated again with every other
/// term in place, alone and beside each of the first candidates (DiagnoseOptions::
/// refine_parameters): the best that lowers the held-out error by the accepted share and the
/// resolution and raises neither half takes the terms' place as a round of its own
/// (LoopRound::replaced), and the loop goes on.
/// When no step passes (DiagnoseOptions::exchange_terms), the kept terms of recorded channels
/// chosen before a later round changed the model (its terms, TL written as the exact norm, the
/// ridge strength) are revisited one at a time: the model without the term (with the later
/// changes) is diagnosed again, and the best of its
/// first eligible candidates that lowers the held-out error of the model with the term by the
/// accepted share and the resolution, raises neither half and passes every other check takes the
/// term's place as a round of its own (LoopRound::replaced); the loop then goes on. A term taken
/// out never comes back through an exchange, and at most three are made.
/// `on_round` (optional) is called after each diagnosis with the round number and the diagnosis.
LoopResult diagnose_loop(const Model& model, const FlightData& data, const std::string& truth,
                         int max_rounds, double min_share, const DiagnoseOptions& options,
                         const std::function<void(int, const Diagnosis&)>& on_round = {},
                         const FlightData* validation = nullptr);

/// The same loop over several flights of one aircraft (same sensors, channels and truth field),
/// for an effect one flight barely shows: each round diagnoses every flight with the model fitted
/// on all of them; a candidate accepted on any flight (explaining `min_share` there) may be added,
/// in the order the flights' diagnoses rank it together (merge_diagnoses); the model is refitted
/// on every flight's calibration rows; and every check (the held-out error, each half of it, the
/// backward pass) is made on the held-out lines of all flights pooled (sample-weighted variance).
/// The pairs' pool takes the residual's channels of every flight; a learned law is drawn on the
/// first flight whose residual stays predictable. With one flight it is the loop above.
/// `on_round` is called after each flight's diagnosis with the round and the flight's index.
LoopResult diagnose_loop(const Model& model, const std::vector<const FlightData*>& flights,
                         const std::string& truth, int max_rounds, double min_share,
                         const DiagnoseOptions& options,
                         const std::function<void(int, size_t, const Diagnosis&)>& on_round = {},
                         const FlightData* validation = nullptr);

}  // namespace magcomp
