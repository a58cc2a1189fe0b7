// magcomp: one round of diagnose_loop (internal to src/core/diagnose): the ways a round may change
// the model, tried in order (a lag with the channel term it was judged with, the first single
// term that passes, a pair of terms that act together, a learned law), each under the loop's
// checks on the held-out lines, then the backward pass. diagnose_loop.cpp runs them.
#pragma once

#include <set>
#include <string>
#include <utility>
#include <vector>

#include "loop_steps.h"
#include "magcomp/core/diagnose/diagnose.h"
#include "magcomp/core/diagnose/diagnose_loop.h"
#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/model/model.h"

namespace magcomp::loop_steps {

// Eligible candidates tried per round, in rank order.
constexpr size_t kTriesPerRound = 3;
/// Round::looking_ahead looks one round ahead only at a runner-up whose held-out error alone is
/// at most this many times the first term's (nT over nT): a cost bound, two diagnoses more per
/// round where it acts. A term that leaves more still has to have its next term explain most of
/// the difference.
constexpr double kLookAheadRatio = 1.5;
/// Exchanges (Round::exchange) made at most over one loop.
constexpr int kExchanges = 3;
/// Eligible candidates (in rank order, after the kept one) tried as look-alikes of a kept term.
constexpr size_t kLookAlikeTries = 6;
/// A kept slow term's time constant is searched again within this factor either way of its own
/// (Round::retimed_slow_term).
constexpr double kSlowRetimeRange = 1.5;
/// ... on a grid of 2 kSlowRetimeSteps + 1 points even in log(tau), then by golden section
/// (scan_parameter); a time constant within this share of the kept one is the kept one.
constexpr int kSlowRetimeSteps = 3;
constexpr double kSlowRetimeTolerance = 0.01;

/// The recorded aircraft states (is_aircraft_state) paired with the one channel of
/// eligible[kept] in a product among `eligible` that explains at least as much as it on both
/// halves (Eligible::explained), in rank order; empty when the kept term reads other than one
/// channel (LoopRound::paired_factors; loop_round.cpp).
std::vector<std::string> paired_factors(const std::vector<Eligible>& eligible, size_t kept);
/// `model` with its term `old_text` written as `spec` (a slow term stays one; a lag written so
/// is the model's only lag), unfitted (loop_revisit.cpp).
Model with_term_as(const Model& model, const std::string& old_text, const std::string& spec);
/// An expression term written with its other projection: "field:S" (a body-fixed field projected
/// on the Earth's field) for "scalar:S" (a reading added to the scalar, nT) and the other way
/// round, the signal S and its parameters unchanged; "" for any other term (loop_revisit.cpp).
std::string other_projection(const TermSpec& t);
/// Kept term k of `model` with every parameter free ('?'; a ramp's knot stays), or "" when it
/// has none to estimate again: not an expression term of recorded channels, one of `start`'s, a
/// learned law's hinge, a slow term (Round::retimed_slow_term estimates its time constant), or a
/// term without a parameter (loop_revisit.cpp).
std::string freed_parameters(const Model& model, size_t k, const Model& start);
/// True when a low-pass of `t` has its corner, 1 / (2 pi tau), below `band_low_hz` (Hz): the
/// low-pass itself puts the term below the band the band-pass stage sizes terms in (a heater's
/// minutes, not a relay's 0.2 s smoothing of a slow channel) (loop_slow_terms.cpp).
bool low_pass_below_band(const TermSpec& t, double band_low_hz);
/// Whether kept term k of `model` may be sized by the slow stage in place of the band-pass: a
/// band-pass fit's term (not slow, not a black box, not one of `start`'s) of recorded aircraft
/// states only (is_aircraft_state: a slow fit of motion or position would size the map's
/// leakage) whose low-pass's corner lies below the band. The band-pass sees such a column only
/// through what little of it its band passes (a heater's field switched on and off), and sizes
/// it there no better than the ridge; the calibration rows, unfiltered, show all of it
/// (loop_slow_terms.cpp).
/// With `lines_size` (DiagnoseOptions::slow_terms_on_lines), a reference fit's term too whose
/// low-pass is kSlowOnLinesMin_s or slower: the calibration rows size it unfiltered, but their
/// few minutes barely move a heater's state; the slow stage sizes it on the lines beside them
/// too (fit.slow_lines), cross-fitted where the loop scores it.
bool slow_form_of(const Model& model, size_t k, const Model& start, bool lines_size = false);
/// Whether term `t` low-passes any signal with a time constant of tau_s or longer.
bool low_pass_beyond(const TermSpec& t, double tau_s);
/// The shortest time constant of a reference fit's term the loop tries sizing on the lines (s):
/// half a minute, slower than any maneuver of the calibration segments (a few seconds each), where
/// a term is a heater's or a drift's state rather than a motion's.
constexpr double kSlowOnLinesMin_s = 30.0;
/// The share of the held-out variance by which a factor of a kept term earns its place below the
/// resolution (Round::factor_resolved): most of what is left, which a chance channel does not
/// explain.
constexpr double kFactorShare = 0.5;
/// The largest relative std (over the flights' samples) of a recorded state that
/// Round::steady_factor_in_place tries as a factor of a kept term beside those the rounds list.
constexpr double kSteadyFactorRelative = 0.1;
/// Whether `lr` raises neither half of the held-out lines above the model scored `now`.
bool halves_hold(const LoopRound& lr, const LoopRound& now);
/// The line numbers of the flights' samples outside the calibration segments (`fit`), sorted.
std::vector<double> lines_beside_calibration(const FitSettings& fit,
                                             const std::vector<const FlightData*>& flights);

/// The indices of the eligible candidates a round tries alone, in rank order: at most
/// kTriesPerRound, the best ranked of each set of recorded channels (a lag, reading none, is
/// always its own).
std::vector<size_t> single_tries(const std::vector<Eligible>& eligible);

// What every step of a round reads: the loop's start model, its flights and their held-out
// halves, the validation flight (or nullptr) and the options.
struct LoopContext {
  const Model& start;
  const std::vector<const FlightData*>& flights;
  const std::string& truth;
  const std::vector<HeldOut>& held_out;
  const FlightData* validation;
  const DiagnoseOptions& options;
  double min_share;
};

/// Over several flights, when no term passes: the terms the flights' diagnoses (with the loop's
/// options, slow candidates sized on the lines as `diagnose` does) name but cannot confirm, each
/// one's channel moving on one half's held-out lines alone (Diagnosis::one_half), judged with the
/// flights as the halves (flight f's held-out samples in half f % 2): Round::first_single on
/// `*result` with the last round rescored so, slow terms sized on `lines` (fit.slow_lines; each
/// half scored with them sized on the other half's flights). When one is kept, `*result` takes
/// it (the backward pass after, with joint_steps) and `*held_out` becomes the flights' halves
/// for the rest of the loop; true then. A channel that moves on the same survey line of every
/// flight lies in one half of each, and only the flights confirm one another
/// (loop_across_flights.cpp).
bool across_flights(const LoopContext& context, int round, const std::vector<double>& lines,
                    LoopResult* result, std::vector<HeldOut>* held_out);

// One round: each step returns true when it kept a change (appended to the result's rounds and
// made its model).
class Round {
 public:
  Round(const LoopContext& context, int round, LoopResult* result)
      : c_(context), round_(round), r_(result) {}

  // A lag ranked first by the share it explains with the channel term it was judged with
  // (Candidate::partner), but not eligible alone: the two together, kept if they pass a pair's
  // checks and lower the held-out error below the first single term that passes (a scalar lag
  // delays every channel's signature; a delayed channel term stands in for it on that channel
  // only).
  bool lag_with_partner(const std::vector<Diagnosis>& dxs, const std::vector<Eligible>& eligible);
  // A set of terms a flight's diagnosis chose together (Diagnosis::joint): fitted on the loop's
  // flights, kept if it passes a single term's checks, each of its terms is needed (without it,
  // each half's error rises by the accepted share of the variance and the resolution), and it
  // lowers the held-out error below the first single term that passes by the same. Over several
  // flights, the best such set.
  bool joint_set(const std::vector<Diagnosis>& dxs, const std::vector<Eligible>& eligible);
  // The eligible candidates in rank order (at most kTriesPerRound, the best ranked of each set
  // of channels): the first that passes every check is kept, with its look-alikes
  // (look_alikes()).
  bool first_single(const std::vector<Eligible>& eligible);
  // Before first_single (DiagnoseOptions::look_ahead): of the eligible candidates as
  // first_single tries them, the first two that pass refusal() alone (the first and the runner-up,
  // of other channels; a lag is its own) are each fitted, the model with it diagnosed with
  // `options`, and the best by held-out error of its single tries that then pass refusal()
  // fitted beside it (at most kTriesPerRound, the best ranked of each set of channels). When the
  // runner-up leaves at most kLookAheadRatio times the first's held-out error alone, and its two
  // rounds improve_on the first's two rounds, the candidates come back with the runner-up first and
  // the first left out (this round's refusals say why); else as they are. One term may stand in for
  // several effects and win its round, while the term of one of them wins the two rounds (a field
  // decay for a scalar lag and an inductive pick-up together).
  std::vector<Eligible> looking_ahead(const std::vector<Eligible>& eligible,
                                      const DiagnoseOptions& options);
  // Effects that act together: when no term passes alone while the residual stays predictable,
  // pairs of terms of distinct channels, fitted together; the best pair by held-out error that
  // passes a pair's checks, of which at least one term fails alone.
  bool pair_acting_together(const std::vector<Diagnosis>& dxs);
  // When no term passes and TL as the exact norm is refused alone (once per loop): the exact
  // norm (exact_norm_forms; fitted against the reference where the flights record it, else the
  // lowest held-out error) diagnosed with `options`, and its first eligible candidates (at most
  // kTriesPerRound, the best ranked of each set of channels) each fitted beside it; the best by
  // held-out error that passes a pair's checks against the norm alone and the term alone
  // (pair_passes) is kept with the norm as the round's terms together. An effect on the
  // calibration rows (a servo's wire drawing current in the maneuvers) pulls a reference fit of
  // TL off unless its term is there too, while under the band-pass TL the effect's term alone
  // does not hold on both halves: each needs the other.
  bool exact_norm_with_a_term(const DiagnoseOptions& options);
  // When nothing else passes: a load's field whose size follows another recorded state of the
  // aircraft (a heater's wire whose pull changes with the outside air temperature), written as
  // the pair current:x + field:x*s, both slow terms sized unfiltered against the reference on
  // the calibration rows and the held-out lines (only where the model's slow terms are sized on
  // the lines too: the loop's round that sizes them there, or fit.slow_lines). A screen on the
  // held-out lines (each line's mean removed) ranks every pair of an electrical channel x and a
  // non-electrical state s that no kept term reads by the share of the error the pair's six columns
  // explain beyond the better of its halves alone (both at least the accepted share); the best
  // kTriesPerRound are fitted, and the best that passes a pair's checks (pair_passes) is kept as
  // the round's terms together. Where the state is steady on the calibration rows, neither term
  // alone holds on lines flown at another value of it, and the band-pass sizes only their sum
  // there.
  bool size_following_a_state();
  // When no term of the language passes while the residual stays predictable: the plain field
  // term of the recorded state that predicts most of it (ExplainableShare::channels), the model
  // fitted again with it at its ridge strength and with the ridge weakened (better_lambda), the
  // better kept if it lowers the held-out error by the accepted share and the resolution and
  // raises neither half (one try per channel over the loop: `named_channels`;
  // DiagnoseOptions::named_channel_term).
  bool named_channel_term(const std::vector<Diagnosis>& dxs, std::set<std::string>* named_channels);
  // When no term of the language passes while the residual stays predictable: a learned law of
  // the channel that predicts most of it (one per channel over the loop: `learned_channels`).
  bool learned_law_of_channel(const std::vector<Diagnosis>& dxs,
                              std::set<std::string>* learned_channels);
  // When nothing else passes: each kept term of a recorded channel or of the Earth's field alone
  // (an eddy decay of B; not the lag; not a learned law's, not one in `taken_out`, not one of the
  // last round that changed the model -- added terms, wrote TL as the exact norm or chose the
  // ridge strength: that round's diagnosis already saw the model as it is) is taken out in turn,
  // the model without it diagnosed with `options`, and
  // the best of that diagnosis's first eligible candidates (at most kTriesPerRound, not the term
  // itself) takes its place if it lowers the held-out error of the model with the term by the
  // accepted share and the resolution, raises neither half and passes refusal(). One exchange
  // per call; the term taken out joins `taken_out`.
  bool exchange(const DiagnoseOptions& options, std::set<std::string>* taken_out);
  // When nothing else passes: the kept terms of recorded channels with parameters (a step's
  // threshold, a time constant, a saturation level, a delay; not a learned law's knots; a slow
  // term's time constant by retimed_slow_term), estimated while other effects were still in the
  // residual or at another ridge strength, have them estimated again with every other term in
  // place: each such term alone, and all of them beside each of the first candidates of `dxs` (at
  // most kTriesPerRound, of distinct channels, whatever their share alone; not within the model's
  // span). The best by held-out error takes their place (and adds its candidate) if it lowers the
  // model's held-out error by the accepted share and the resolution (a slow term retimed below
  // the band: the share alone, improves_in_place), raises neither half and passes refusal(); with a
  // candidate, it lowers each half's error by the accepted share and the resolution, and the
  // error of the best without one (when one passes) by the same. A kept band-pass term of
  // aircraft states whose low-pass lies below the band (slow_form_of) is
  // also tried sized by the slow stage in its place, judged by moves_to_slow_stage: a heater's
  // field chosen in its band-pass form by a hair on the held-out lines, whose size the band
  // only guesses, leaves the calibration rows (and another flight's) unexplained. A reference
  // fit's term of kSlowOnLinesMin_s or slower is tried sized on the calibration rows and the
  // lines beside them (fit.slow_lines, set to them when empty), judged by improves_on: the
  // calibration rows sized it already, on minutes in which a heater's channel may not switch.
  // Terms whose text is in `fixed` keep their parameters.
  bool refine_parameters(const std::vector<Diagnosis>& dxs,
                         const std::set<std::string>& fixed = {});
  // Kept slow term k of `model` (Model::slow_terms, one fixed low-pass in its chain) with its
  // time constant estimated again with every other term in place, by what the slow stage fits:
  // the error on the calibration rows (LoopRound::calibration_std_nT, unfiltered), searched in
  // log(tau) within a factor kSlowRetimeRange of the kept time constant (scan_parameter). A
  // heater's time constant estimated while another heater was still in the residual is off by a few
  // percent, which leaves its field's steps half-written. Its spec, or "" when no other time
  // constant does better there (within kSlowRetimeTolerance of the kept one).
  std::string retimed_slow_term(const Model& model, size_t k) const;
  // When nothing else passes or changes (and when the loop's rounds are spent): a kept product
  // of recorded channels (field:a*b, with its
  // transforms) whose factor earns no place -- the product does not beat the same term without
  // that factor by factor_resolved on the held-out lines (a factor the flights hold steady, or
  // one that only rescales the other) -- is written without it, if that
  // term alone still lowers the error of the model without either by the same and passes
  // refusal() against it. The least needed factor first, one per call; the change is a round
  // (LoopRound::replaced says why).
  bool drop_idle_factors();
  // When nothing else passes or changes (and when the loop's rounds are spent): a kept field term
  // of one recorded channel (its transforms linear, not a learned law's hinge nor a slow term)
  // gives way to its product with a factor the rounds listed beside it as a channel these
  // flights hold nearly steady (LoopRound::steady_factors), with a recorded state held within
  // kSteadyFactorRelative of its mean, or with a state a product of its round paired it with
  // (LoopRound::paired_factors), when, with every other term in place,
  // the product passes refusal(), raises neither half, earns its factor (factor_resolved) and
  // holds where the term is sized (holds_where_sized). A modulation of a few percent is below
  // what a term alone must gain while other effects are in the residual; once they are
  // written, it is what remains. The best product, one per call; it is a round
  // (LoopRound::replaced says why), and drop_idle_factors keeps it by the same test.
  bool steady_factor_in_place();
  // When nothing else passes or changes (and when the loop's rounds are spent): a kept term of
  // recorded channels (not a learned law's hinge; a slow term with
  // DiagnoseOptions::slow_look_alikes, sized as a slow term in its place) gives way to one of its
  // look-alikes (look_alikes_of) when, with every other term in place, the look-alike lowers the
  // held-out error as a parameter estimated again must (improves_in_place: the accepted share of
  // its variance, neither half worse): once the other effects are written, what the two channels
  // differ by (a ratio that follows a third channel) is no longer buried under them, and a tie
  // keeps the name the round chose. The best swap, one per call; it is a round
  // (LoopRound::replaced says why).
  bool better_look_alike_in_place();
  // When nothing else passes or changes (and when the loop's rounds are spent): a kept term of
  // recorded channels (not a learned law's hinge, not one in `dropped`) that another kept term,
  // its parameters estimated again without it (a freed threshold, time constant, saturation or
  // delay; a slow term's time constant by retimed_slow_term), makes redundant leaves: against
  // that model the term explains neither the accepted share of the held-out variance nor the
  // resolution, and that model raises neither the validation flight's error by the accepted
  // share nor the calibration rows' by half again and the resolution. A flex's time
  // constant estimated while another effect was still in the residual is a few percent off, and
  // a second channel that moves with the first (a lateral acceleration beside the yaw rate)
  // writes the difference; with the time constant estimated again, the second channel is
  // redundant. The best such drop by held-out error, one per call; the term joins `dropped`.
  bool redundant_once_refined(std::set<std::string>* dropped);
  // The look-alikes of kept term `t`: those the rounds listed beside a term of its channels
  // (LoopRound::look_alikes), and `t` with one of its channels replaced by each recorded state
  // of the aircraft or angular rate (source_fields without the full search; not an earth-frame
  // velocity, not one of `model_fields`) that moves with it on every flight
  // (|r| >= kLookAlikeCorrelation).
  std::vector<std::string> look_alikes_of(const TermSpec& t,
                                          const std::set<std::string>& model_fields) const;
  // As the loop ends, over one flight without a validation flight: a kept term of a drift
  // (a low-pass of kSlowOnLinesMin_s or slower) of recorded states no other kept term reads,
  // not in `audited`, leaves when, with every other term in place, its share of the held-out
  // variance (the smaller half's) is not beyond_chance of what the search finds with those
  // states read shifted in time (chance_level of the model without it, with `options`, among
  // the shifted terms no slower than it: term_correlation_time_s at most its own), and the
  // model without it leaves no more on the held-out lines than the loop's start model (the
  // first round's score): a drift the rest of the model was fitted around stays. Over
  // one flight, a trend of minutes has few independent values, and the search tries thousands
  // of them: one may follow the residual by chance, and another flight then reads it where it
  // does not. The first such term in the model's order, one per call (its removal is said in the
  // last round's LoopRound::removed); each term tried joins `audited`.
  bool drop_chance_slow_term(const DiagnoseOptions& options, std::set<std::string>* audited);
  // Once drop_chance_slow_term has taken `drift` out: what the model took in together with it
  // (its round's LoopRound::added) or after it leaves, one at a time, while the model without it
  // leaves less on the held-out lines: a term, or TL's exact norm (its bias and norm out, the
  // fit's method and ridge strength as the model before that round had them). Each was sized
  // with the drift in place, and without the drift one may only fit what the drift explained
  // (a set is accepted for what it does together; the exact norm fitted against the reference
  // absorbs what it leaves). Each is said in the last round's LoopRound::removed; the count
  // that left.
  int shed_after_chance_drift(const std::string& drift);
  // An earlier round's term that the model no longer needs leaves (the least needed first, one
  // at a time), so long as the round still lowers the error of the round before it.
  void backward_pass();
  // The changes refused this round that no kept change carried: (what, why).
  const std::vector<std::pair<std::string, std::string>>& rejected() const { return rejected_; }
  // Records a term refused before any step tried it (a term within the model's own span).
  void refuse(std::string what, std::string why) {
    rejected_.emplace_back(std::move(what), std::move(why));
  }

 private:
  // The round's change kept: `lr` (its scores and reasons) takes the refusals recorded so far
  // and becomes the loop's last round, `next` its model.
  void keep(Model next, LoopRound lr);
  // Fits `next` and keeps it if it passes every check; else records why in rejected_.
  bool try_model(Model next, const std::string& added, double explained, bool black_box);
  // `m` fitted on the flights and scored.
  std::pair<Model, LoopRound> fit_score(Model m) const;
  // On one half of the held-out lines: the accepted share of the variance and the resolution.
  bool passes(double with_nT, double without_nT) const;
  // A change scored `lr` against the model scored `now`: it passes refusal(), raises neither
  // half, and lowers the held-out error by passes().
  bool improves_on(const LoopRound& lr, const LoopRound& now) const;
  // The same for a kept slow term's time constant estimated again (retimed_slow_term) when its
  // low-pass's corner lies below the fit's band: every check but the resolution. The
  // resolution is what a new channel must gain over the held-out lines' noise, where the lines
  // choose it; a time constant the slow stage estimates on the calibration rows adds no channel,
  // and the lines only confirm it, by the accepted share of their variance with neither half
  // higher. A term's freed parameters, and a fast low-pass of a slow channel (a relay's
  // smoothing), keep the resolution: a small gain there takes the round in which an exchange of
  // the term would have gained more.
  bool improves_in_place(const LoopRound& lr, const LoopRound& now) const;
  // Whether a kept term's factor earns its place: the model with the product (`with`) beats the
  // same model with the term without the factor (`without`) by passes(); or, the gain below the
  // resolution, by kFactorShare of the held-out variance, each half lowered by the accepted
  // share of its own (a half already near its noise floor has little left to lose). A factor the
  // flights hold nearly steady (an engine speed within a few percent) modulates a term by less
  // than a term must gain, yet once every other effect is written that modulation is most of
  // what remains.
  bool factor_resolved(const LoopRound& with, const LoopRound& without) const;
  // A kept term moved from the band-pass to the slow stage (slow_form_of),
  // scored `lr` against the model scored `now`: it passes refusal(), lowers the calibration
  // rows' error (unfiltered: what the slow stage sizes it on) and the held-out error each by the
  // accepted share of the variance, and raises neither half by what a term must gain there
  // (passes()). The held-out lines hold such a term's channel nearly steady (a heater's field
  // settles within a line), so a half may move by what its noise moves it; the change adds no
  // channel.
  bool moves_to_slow_stage(const LoopRound& lr, const LoopRound& now) const;
  // A look-alike scored `lr` in place of the kept term of the model scored `now` describes the
  // same effect no worse where both are sized: on the calibration rows its error (unfiltered) is
  // not above the kept term's by more than the accepted share of the variance. A look-alike that
  // gains on the held-out lines while it fits those rows worse gains through a part of its
  // channel the fit never sized there (a bus voltage's slow wander beside its sag under the
  // load the kept current draws), which this flight's lines follow and another flight's do not.
  // True when either error is unknown.
  bool holds_where_sized(const LoopRound& lr, const LoopRound& now) const;
  // A pair fitted together (`lr`): every check of a single term, passes() on each half, and
  // each of its terms needed (the pair lowers the error variance of each alone by the accepted
  // share).
  bool pair_passes(const LoopRound& lr, const LoopRound& alone_a, const LoopRound& alone_b) const;
  // Keeps terms fitted together as this round, with each one's held-out error alone (nT).
  void keep_together(std::pair<Model, LoopRound> fitted, const std::vector<std::string>& terms,
                     const std::vector<double>& alone_nT);
  // The held-out error of the first of the eligible candidates (as first_single tries them) that
  // passes refusal() alone, nT; infinity when none does.
  double first_single_nT(const std::vector<Eligible>& eligible) const;
  // After eligible[kept] was kept in place of `before`: of the eligible terms of the same
  // channels with fewer columns (a drift of the reading beside the field of the same current),
  // the best by held-out error that passes the same checks and that the kept one does not beat by
  // the accepted share of the variance and the resolution takes its place: a term's extra columns
  // must earn their place on the held-out lines. Returns the index now kept.
  size_t fewer_columns(const Model& before, const std::vector<Eligible>& eligible, size_t kept);
  // After eligible[kept] was kept in place of `before`: the eligible terms of other channels
  // (at most kLookAlikeTries, in rank order) that, each in its place, pass the same checks and
  // that the kept one does not beat by the accepted share and the resolution
  // (LoopRound::look_alikes). With DiagnoseOptions::better_look_alike, the best of them that
  // beats the kept term so, as a step beats the model it changes (refusal() and passes() on the
  // held-out lines), takes its place, and its own look-alikes are listed.
  // Returns the index now kept.
  size_t look_alikes(const Model& before, const std::vector<Eligible>& eligible, size_t kept);

  // `fitted`, the model with kept term `old_text` written as `new_text`, becomes a round of its
  // own (LoopRound::replaced gives `why`; the round's refusals go with it).
  void replaced_as_round(std::pair<Model, LoopRound> fitted, const std::string& old_text,
                         const std::string& new_text, const std::string& why);
  // `term`, fitted in place of the last round's kept term (`fitted`), becomes that round: the
  // term it replaces joins the round's refusals with `why`, its look-alikes are dropped.
  void in_place_of_kept(std::pair<Model, LoopRound> fitted, const Eligible& term,
                        const std::string& why);

  const LoopContext& c_;
  int round_;
  LoopResult* r_;
  std::vector<std::pair<std::string, std::string>> rejected_;
};

}  // namespace magcomp::loop_steps
