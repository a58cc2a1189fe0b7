// magcomp: the steps of diagnose_loop (internal to src/core/diagnose): scoring a model on the
// held-out lines of its flights, refusing it, a channel's learned law, adding and removing terms,
// and the candidates a round may add. diagnose_loop.cpp runs them.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "magcomp/core/diagnose/diagnose.h"
#include "magcomp/core/diagnose/diagnose_loop.h"
#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/model/model.h"

namespace magcomp::loop_steps {

// Each flight's held-out samples, in two halves: the first diagnosis's split of that flight
// (Diagnosis::heldout_fold: 0 selection, 1 confirmation, -1 not held out), and the flight's line
// of each sample (each line's mean is removed).
struct HeldOut {
  std::vector<signed char> fold;
  Eigen::VectorXd line;
};

/// Scores of a model: held-out lines, all lines, FOM, validation flight. Over several flights,
/// each figure is pooled over the flights' samples (the FOM: their mean). nT.
LoopRound score(const Model& model, const std::vector<const FlightData*>& flights,
                const std::string& truth, const std::vector<HeldOut>& held_out,
                const FlightData* validation);

/// `lr`'s scores (held out, halves, all lines, calibration rows, per flight and per line, FOM,
/// validation, the channel terms) taken from `scored`, the same model scored again or the model
/// that replaces it; its round, terms and reasons stay.
void take_scores(const LoopRound& scored, LoopRound* lr);

/// The ridge strength (fit.lambda) chosen on the held-out samples: `model` (scored `now`)
/// refitted with `ceiling` (the loop's start model's fit.lambda) and 1/10, 1/100 and 1/1000 of it
/// (but its own), and the one with the lowest held-out error, if it lowers that error by the
/// accepted share and the resolution, lowers it on each half, and passes `refusal`. Nullopt when
/// the model's own strength stays. Never above the ceiling: a stronger ridge than the user's
/// lowers the held-out error where an effect the model lacks leaks into its columns (their fit
/// shrinks with the leak), which hides the effect instead of writing it.
std::optional<std::pair<Model, LoopRound>> better_lambda(
    const Model& model, double ceiling, const LoopRound& now,
    const std::vector<const FlightData*>& flights, const std::string& truth,
    const std::vector<HeldOut>& held_out, const FlightData* validation,
    const DiagnoseOptions& options);

/// The forms of TL as the exact norm that exact_norm_step tries for `model`, unfitted, each with
/// its fit's change in words ("" when the fit stays): `model` with `norm`, and, when it is a
/// band-pass fit with no slow term and every flight records `truth`, with `norm` and `bias`
/// fitted against `truth` on the same calibration segments at the model's ridge strength and
/// 1/100 of it. None when the model already has `norm`.
std::vector<std::pair<Model, std::string>> exact_norm_forms(
    const Model& model, const std::vector<const FlightData*>& flights, const std::string& truth);

/// TL written as the exact norm (DiagnoseOptions::exact_norm): `model` (scored `now`) with the
/// `norm` term under its own fit, and, when it is a band-pass fit with no slow term and every
/// flight records `truth`, with `norm` and `bias` fitted against `truth` on the same calibration
/// segments at the model's ridge strength and 1/100 of it; the one with the lowest held-out error,
/// kept as better_lambda keeps a strength (its LoopRound's `explained` set: the share of the
/// held-out error variance it removes). Second: the fit's change in words ("" when it stays).
/// Nullopt when the model already has `norm` or none passes.
std::optional<std::pair<std::pair<Model, LoopRound>, std::string>> exact_norm_step(
    const Model& model, const LoopRound& now, const std::vector<const FlightData*>& flights,
    const std::string& truth, const std::vector<HeldOut>& held_out, const FlightData* validation,
    const DiagnoseOptions& options);

/// Why a scored candidate model is refused against the current one ("" when it is kept): its
/// held-out error does not fall, its validation flight's error does not fall, or its error on
/// the calibration rows (LoopRound::calibration_std_nT) rises by half again and the resolution
/// (DiagnoseOptions::check_calibration_rows).
std::string refusal(const LoopRound& next, const LoopRound& now, const DiagnoseOptions& options);
/// The name of one half (0 or 1) of the held-out samples in a refusal's words: "the selection
/// half" or "the confirmation half", or, once the loop `r` judges with the flights as the halves
/// (a round with LoopRound::flight_halves, loop_steps::across_flights), the flights of `flights`
/// it holds (flight f, counted from 1, in half (f - 1) % 2).
std::string half_name(const LoopResult& r, size_t flights, int half);
/// Whether the change scored `next` raises the error on the calibration rows (unfiltered) of the
/// model scored `now` by half again and `resolution_nT` (nT): its sizes do not hold where they are
/// fitted. False when either error is unknown.
bool raises_calibration_rows(const LoopRound& next, const LoopRound& now, double resolution_nT);

/// A learned law of `channel` on `data` (hinges at its quantiles through the linear transforms
/// of `shape`); empty when the channel cannot carry one (loop_steps.cpp says when).
std::vector<TermSpec> learned_law(const std::string& channel, const Candidate* shape,
                                  const Model& model, const FlightData& data);

/// Adds a candidate's term to `m`; a slow one (Candidate::slow) joins Model::slow_terms, fitted
/// against `truth` unless the model names its own reference.
void add_candidate_term(const TermSpec& term, bool slow, const std::string& truth, Model* m);

/// The recorded channels a term reads (none for a lag).
std::set<std::string> fields_of(const TermSpec& t);
/// The recorded channels the model's terms read.
std::set<std::string> fields_of(const Model& model);

/// The terms of a round's step as LoopRound::added writes them (" + " joins a pair or a law).
std::vector<std::string> step_terms(const std::string& added);

/// The rounds with each lag a later lag displaced written as replaced: a model has one lag
/// (Model::add_term), so a step adding lag:T while `start` or an earlier step holds another
/// lag takes that lag's place, whatever else the step's own replaced list names. Each such
/// entry is appended to that step's replaced list, so the rounds read what the model holds.
void record_displaced_lags(const Model& start, std::vector<LoopRound>* rounds);

/// The shifts of the chance level (chance_level): a quarter, a half and three quarters of each
/// flight's length.
constexpr double kChanceShifts[] = {0.25, 0.5, 0.75};
/// Whether recorded channel `name` is read shifted in time by chance_level: a recorded state of
/// the aircraft (is_aircraft_state) that neither `model` reads nor is its scalar or `truth`.
bool shiftable_channel(const std::string& name, const Model& model, const std::string& truth);
/// Whether term `t` reads recorded channels, each of them shiftable_channel.
bool reads_shiftable_channels_only(const TermSpec& t, const Model& model, const std::string& truth);
/// `data` with each shiftable_channel rotated by `fraction` of its length (sample i reads sample
/// i - fraction n, circularly); every other channel (the magnetometers, the INS, the model's
/// channels, the lines) as recorded.
FlightData with_states_shifted(const FlightData& data, const Model& model, const std::string& truth,
                               double fraction);
/// What the search finds by chance among terms of recorded states: the largest share of the
/// held-out variance (Candidate::explained_fraction, the smaller of the two halves') that an
/// accepted candidate reading only shiftable channels explains when `model` is diagnosed with
/// `options` on `flights` whose shiftable channels are rotated by each of kChanceShifts.
/// Rotated, a state has nothing to do with the residual, yet keeps its own spectrum: a slow
/// trend of minutes matches another over a flight of an hour by chance, and the search tries
/// thousands of them. 0 when no such candidate is accepted.
/// Only candidates whose signal is no slower than `slowest_s` count (its correlation time,
/// term_correlation_time_s, on the shifted flight): a slower trend has fewer independent values
/// and matches by chance more often, so a term is compared with chance terms of its own pace.
struct ChanceLevel {
  double share = 0.0;          ///< the largest share explained (dimensionless, 0..1)
  std::string term;            ///< the term that explains it, as read shifted
  double fraction = 0.0;       ///< its shift, a fraction of the flight's length
  double correlation_s = 0.0;  ///< its signal's correlation time on the shifted flight, s
  std::string slower_term;     ///< the best slower candidate left out ("" when none beat it)
  double slower_share = 0.0;   ///< its share (dimensionless)
};
ChanceLevel chance_level(const Model& model, const std::vector<const FlightData*>& flights,
                         const std::string& truth, const DiagnoseOptions& options,
                         double slowest_s = std::numeric_limits<double>::infinity());
/// The correlation time (correlation_time_s) of the signal of term `t` of the language on
/// `data`, s (the first component of a vector signal); NaN for a fixed term.
double term_correlation_time_s(const TermSpec& t, const Model& model, const FlightData& data);
/// Whether a share `explained` of the held-out variance (0..1) is beyond `chance`: what it
/// leaves, 1 - explained, is at most what two draws of chance in turn leave, (1 - chance)^2 (the
/// chance level's term on the residual, and another on what that term leaves). Three shifts
/// give the best of three draws of the search, which a fourth draw beats one time in four;
/// hence the second draw. Any accepted share is beyond a chance level of 0 (no term of the
/// shifted states accepted).
inline bool beyond_chance(double explained, const ChanceLevel& chance) {
  return 1.0 - explained <= (1.0 - chance.share) * (1.0 - chance.share);
}
/// Whether a drift is beyond `chance` down to the resolution: with every other term in place the
/// model leaves `left_nT` held out (nT), at most `resolution_nT`, nothing the search resolves,
/// while the chance level's term would leave at least `resolution_nT` more of `without_nT` (the
/// held-out error without the drift): sqrt(1 - share) without_nT. Where chance explains nearly
/// everything, the second draw of beyond_chance asks the drift to leave less than the search can
/// resolve (chance 96.9 % asks for 99.9 %); this asks what the search can tell.
inline bool beyond_chance_to_the_resolution(double left_nT, double without_nT,
                                            const ChanceLevel& chance, double resolution_nT) {
  return left_nT <= resolution_nT &&
         std::sqrt(std::max(1.0 - chance.share, 0.0)) * without_nT >= left_nT + resolution_nT;
}

/// `m` without `term` (and out of its slow and black-box lists), unfitted.
Model without_term(const Model& m, const TermSpec& term);

/// True when `term` was added to `start` purely (it replaced nothing of the start model).
bool removable(const Model& start, const TermSpec& term);

/// True when kept term `term` of `model` may be written again by a step that revisits the kept
/// terms: added to `start` purely (removable), and neither a learned law's hinge
/// (Model::black_box_terms) nor, unless `slow_too`, a slow term (Model::slow_terms: its stage and
/// lines are sized for the term as it is; a step that writes another term in its place in the
/// slow list passes `slow_too`).
bool revisable(const Model& start, const Model& model, const TermSpec& term, bool slow_too = false);

/// The share of `with`'s error variance that a change to `without` would add (negative when the
/// change lowers the error).
double variance_share(double with_nT, double without_nT);

// A candidate the loop may add.
struct Eligible {
  TermSpec term;
  bool slow = false;
  double explained = 0.0;  ///< its conservative explained share (on the flight it is taken from)
  double base_span_share = NAN;  ///< Candidate::base_span_share (on that flight)
};

/// A channel's relative std over `flights` (std / |mean| of its finite samples pooled over
/// them), dimensionless; NaN when fewer than two are finite or the mean is 0. Every flight must
/// record the channel.
double pooled_relative_std(const std::vector<const FlightData*>& flights, const std::string& name);

/// The recorded states of the aircraft (is_aircraft_state, not among `kept_channels` nor the
/// reference `truth`) that `flights` hold so steady that a term of `term_nT` (the std it
/// explains on the held-out lines) times one of them differs from it by less than
/// `resolution_nT`: their relative std (std / |mean| over the flights' samples) times term_nT is
/// below it. Each with that relative std (dimensionless), steadiest first.
std::vector<std::pair<std::string, double>> steady_factors(
    const std::vector<const FlightData*>& flights, const std::set<std::string>& kept_channels,
    const std::string& truth, double term_nT, double resolution_nT);

// A look-alike's ratio follows a channel when Pearson's |r| of the two reaches this, over at
// least kLookAlikeRatioMinSamples samples (look_alike_ratio).
constexpr double kLookAlikeRatioFollows = 0.9;
constexpr size_t kLookAlikeRatioMinSamples = 50;

/// What would tell two look-alike terms' channels apart on `flights`: the recorded channel (a
/// state of the aircraft or motion and air data; not a position, bookkeeping, `truth` or one of
/// the terms' channels) that the ratio of the product of the `kept` channels to the product of
/// the `alike` channels follows most closely (Pearson's |r| at least kLookAlikeRatioFollows),
/// over the samples where |alike's product| reaches half its 95th percentile on its flight. A
/// term of two or three channels is also read through each part of them (a product with a bus
/// the flights hold steady: the ratio of the moving channels), and the closest of all is kept;
/// the channels the ratio reads are joined with "*" in the result, its `term` left empty.
/// Nullopt when no channel follows the ratio (channels proportional on these flights, or a
/// relation no single recorded channel carries), or when the two sets share a channel.
std::optional<LookAlikeRatio> look_alike_ratio(const std::vector<const FlightData*>& flights,
                                               const std::set<std::string>& kept,
                                               const std::set<std::string>& alike,
                                               const std::string& truth);

/// The candidates of one round's diagnoses that the loop may add, in rank order (see
/// diagnose_loop); a term within the model's own span (within_model_span) only with
/// `within_span_too`.
std::vector<Eligible> eligible_candidates(const std::vector<Diagnosis>& dxs, double min_share,
                                          bool within_span_too = false);

}  // namespace magcomp::loop_steps
