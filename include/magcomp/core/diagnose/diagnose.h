// magcomp: which physical effect is the model missing? A search over the term language, ranked on
// lines the fit never saw and confirmed on lines used neither to fit nor to choose, and an honest
// verdict on what remains.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "magcomp/core/diagnose/associations.h"
#include "magcomp/core/diagnose/explainable_share.h"
#include "magcomp/core/diagnose/one_half_term.h"
#include "magcomp/core/diagnose/residual_floor.h"
#include "magcomp/core/io/channel_kinds.h"
#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/model/model.h"

namespace magcomp {

/// One candidate effect, evaluated by adding its term to the model and refitting on the fit rows.
struct Candidate {
  TermSpec term;  ///< written as exactly what `--term` accepts (estimated parameters as numbers)
  std::string effect;         ///< its physics in words
  std::string channel;        ///< the channel(s) it uses ("" if none)
  std::string family;         ///< the kind of effect searched: tl, current, rate, thermal, lag, ...
  double std_after_nT = 0.0;  ///< held-out error std (line means removed) with the term, nT
  /// The conservative share of the held-out error variance it explains: the smaller of its share
  /// on the selection lines and on the confirmation lines.
  double explained_fraction = 0.0;
  double explained_selection = 0.0;     ///< 1 - (std_after / baseline)² on the selection lines
  double explained_confirmation = 0.0;  ///< the same on the confirmation lines
  /// The share it is ranked by: its selection share, or for a lag the selection share of the lag
  /// together with the channel term whose timing it explains (added in the next round).
  double ranking_share = NAN;
  /// The term ranking_share was measured with (a lag's channel term), empty when none.
  TermSpec partner;
  /// True when it improves the selection lines (where it was ranked) and also the confirmation
  /// lines (used neither to fit nor to choose it) by at least DiagnoseOptions::accept_fraction
  /// of the variance and DiagnoseOptions::resolution_nT of the std (on a half under three
  /// resolutions, for a term outside the base's span: 25 % of its variance, with the resolution
  /// gained over all held-out lines);
  /// or, for the one candidate
  /// chosen_on_confirmation, the confirmation lines by both, the selection lines by
  /// accept_fraction, and the held-out error by resolution_nT more than the selection lines'
  /// first.
  bool accepted = false;
  /// Ranked first on the confirmation lines and confirmed on the selection lines (an effect that
  /// barely shows on the selection lines); false for a term chosen on the selection lines.
  bool chosen_on_confirmation = false;
  /// fitted size in physical units, e.g. "19.2 nT/A, lp.time_constant_s 150"
  std::string estimate;
  /// Estimated parameters in physical units: {"lp.time_constant_s", 150}, {"lag_s", 0.3},
  /// {"gain_nT_per_unit", 19.2}, ...
  std::vector<std::pair<std::string, double>> parameters;
  /// Too slow for the model's band-pass fit: scored, and to be added, as a slow term
  /// (Model::slow_terms: fitted after the band-pass stage against the reference, unfiltered, on
  /// the calibration segments).
  bool slow = false;
  /// The share (0..1) of a trained network's attribution on the channels this term reads
  /// (DiagnoseOptions::network_channels, the leading ones): 0 when none is given or read.
  double network_share = 0.0;
  /// The share (0..1) of its columns' energy on the fit rows that the model's own columns there
  /// already span (NaN for a slow term): near 1, the term adds no direction of its own and only
  /// moves the ridge's hold on the model's coefficients.
  double base_span_share = NAN;
  /// How well the rows that size it (the fit rows; a slow term's: the slow stage's) size it, as
  /// term_support measures a loop's added terms: its size over the flight, nT (the std of its
  /// field beyond what the model's other columns and a constant take), and that size's std by
  /// the jackknife over 20 contiguous blocks of those rows, each left out in turn, nT. NaN when
  /// not computed (the lag; beyond the first 3 accepted candidates).
  double size_nT = NAN, size_sigma_nT = NAN;
  /// Each coefficient's jackknife std, in its unit (nT per unit of its column).
  std::vector<double> coefficient_sigma;
  /// Times its first channel (`switches_channel`) switched on those rows (channel_switches);
  /// -1 when not computed or the term reads no channel.
  int switches = -1;
  std::string switches_channel;
};

/// A term whose fit-row columns lie this much within the model's own span
/// (Candidate::base_span_share; within 1 % of their amplitude) adds no direction of its own: its
/// columns there are the model's own times its channel's level, so its size is the ridge's split
/// of that level, and another flight's level is read through it.
constexpr double kWithinSpanShare = 0.9999;

/// True when a term's share of fit-row energy within the model's own span
/// (Candidate::base_span_share, 0..1) is kWithinSpanShare or more: diagnose_loop never adds it.
/// False for NAN (a slow term, the lag).
inline bool within_model_span(double base_span_share) {
  return base_span_share >= kWithinSpanShare;
}

/// A recorded channel a trained network leans on: its share (0..1) of the channels' importance in
/// the network's attribution (permutation importance on a flight it never saw: `magcomp
/// evaluate --explain --json`).
struct NetworkChannel {
  std::string channel;
  double share = 0.0;
};
/// The channels of an attribution diagnose reads: at most kNetworkChannels, each with at least
/// kNetworkMinShare of the importance.
constexpr size_t kNetworkChannels = 3;
constexpr double kNetworkMinShare = 0.10;

/// DiagnoseOptions::slow_lines_first: a slow candidate sized on the held-out lines is tried
/// first when it explains this share of the held-out error (conservative, 0..1) and this many
/// times the share of the first candidate the calibration rows size.
constexpr double kSlowLinesFirstShare = 0.5;
constexpr double kSlowLinesFirstRatio = 2.0;

/// What diagnose found of a channel the network leans on (Diagnosis::network).
struct NetworkCheck {
  std::string channel;
  double share = 0.0;  ///< the network's share on it (0..1)
  /// Its terms were among the candidates; false with the reason in `why_not` (not in the data,
  /// constant or gappy, a position: leakage of the map or the trajectory, never a term).
  bool searched = false;
  std::string why_not;
  /// The best ranked candidate that reads it (empty when none): its own terms first, unless a
  /// term with another channel (a product) is accepted above them; its shares of the held-out
  /// variance on the selection and confirmation lines, and whether it is accepted.
  std::string best_term;
  double explained_selection = NAN, explained_confirmation = NAN;
  bool accepted = false;
};

/// Settings of a diagnosis (defaults: the full search).
struct DiagnoseOptions {
  /// Every field, every transform family; false: the aircraft's state channels
  /// (is_aircraft_state) and the attitude rates only.
  bool full_search = true;
  double accept_fraction = 0.02;  ///< the share a term must explain on both nested splits
  /// Search the channels that record a constant and their white noise only (records_noise_only:
  /// a regulated rail) too, keeping a term that reads one only where it explains at least
  /// kRailShare of the held-out variance on both splits (false: leave them out).
  bool search_rails = true;
  /// The smallest error that counts, nT: a term must lower the held-out error std by this much on
  /// both splits, and a predictable remainder smaller than this (rms) is called noise.
  double resolution_nT = 0.03;
  int threads = 2;                ///< worker threads for the search
  bool explainable_share = true;  ///< estimate what a flexible model of all channels predicts
  /// diagnose_loop: try pairs of terms together when no term passes alone, and drop earlier
  /// terms that later ones made redundant (false: one term at a time, never removed).
  bool joint_steps = true;
  /// diagnose_loop: choose the ridge strength (fit.lambda) on the held-out lines before each
  /// round's terms (false: keep the model's; doc/diagnose.md says what it gains and costs).
  bool choose_lambda = false;
  /// diagnose_loop: when a round's first term lies within the model's own span
  /// (Candidate::base_span_share), choose the ridge strength as choose_lambda does before adding
  /// it (false: add such a term as any other).
  bool ridge_for_span_terms = true;
  /// diagnose_loop: never add a term that lies within the model's own span on the fit rows
  /// (Candidate::base_span_share at kWithinSpanShare or more): its columns there are
  /// the model's own times its channel's level, so its size is the ridge's split of that level,
  /// and another flight's level is read through it (false: such a term is judged as any other
  /// once the ridge step is refused).
  bool refuse_within_span_terms = true;
  /// diagnose: choose a set of terms together (Diagnosis::joint, joint_selection.cpp), which
  /// diagnose_loop tries before the first single term (false: single terms and pairs only).
  bool joint_selection = true;
  /// diagnose_loop: refuse a step that raises the unfiltered error on the model's calibration
  /// rows by half again and resolution_nT (LoopRound::calibration_std_nT; false: the held-out lines
  /// and the validation flight alone decide).
  bool check_calibration_rows = true;
  /// A slow term (a drift of minutes, Model::slow_terms) is sized on the held-out lines too,
  /// where its channel moves, not on the calibration rows alone, where it barely does: diagnose
  /// scores each half with the size fitted on the calibration rows and the other half's lines,
  /// and diagnose_loop's model carries those lines as fit.slow_lines (false: the calibration
  /// rows alone size it).
  bool slow_terms_on_lines = true;
  /// diagnose_loop, with slow_terms_on_lines: while the model's slow terms are sized on the
  /// calibration rows, each round also diagnoses them sized on the held-out lines, and tries
  /// that round first when a slow candidate there explains kSlowLinesFirstShare of the held-out
  /// error and kSlowLinesFirstRatio times the share of the calibration rows' first candidate: a
  /// drift that dominates the flight goes in before the small terms that would otherwise stand in
  /// for parts of it (false: the lines only when the calibration rows keep nothing).
  bool slow_lines_first = true;
  /// Every step candidate's threshold, scanned on the calibration rows, is moved within the
  /// thresholds those rows cannot tell apart (the 95 % profile-likelihood interval) to the one
  /// that leaves the selection lines the lowest error (false: the calibration rows alone place
  /// it; diagnose_loop places a kept step's threshold so, place_thresholds_again).
  bool thresholds_on_selection = false;
  /// With slow_terms_on_lines, TL's second-order term (`second_order`: 15 columns quartic in
  /// the field's direction beside TL's 18, which the calibration segments cannot size) is also
  /// sized as a slow term on the calibration rows and the held-out lines, cross-fitted, and the
  /// better of that and the band-pass on the selection lines is scored (false: the band-pass
  /// alone sizes it).
  bool second_order_on_lines = true;
  /// diagnose_loop: before the first round's terms, TL written as the exact norm (the `norm`
  /// term: the scalar is |B + v|, TL's first-order expansion drops a part second order in the
  /// aircraft's field that no channel carries) and, where the flights record the reference field
  /// and the model has no slow term, fitted against it on the calibration segments (with a bias, at
  /// the model's ridge strength and 1/100 of it): a band-pass fit cannot size that part beside TL's
  /// columns. Kept as any step is: it lowers the held-out error by the accepted share and the
  /// resolution, and on both halves (false: the model's TL as given).
  bool exact_norm = true;
  /// diagnose_loop, with exact_norm and joint_steps: when no term passes and TL as the exact norm
  /// is refused alone, once per loop, the exact norm is diagnosed and each of its first
  /// candidates fitted beside it; the best pair that passes a pair's checks (each is needed: the
  /// two lower the held-out error of the norm alone and of the term alone by accept_fraction of
  /// the variance, each half by the resolution) is kept together (loop_steps::Round::
  /// exact_norm_with_a_term). An effect on the calibration rows pulls a reference fit of TL off
  /// unless its term is there too (false: the exact norm is only tried alone).
  bool norm_with_a_term = true;
  /// diagnose_loop over several flights: when no term passes, a term that a flight's diagnosis
  /// names but its held-out lines cannot confirm, its channel moving on one half's lines alone
  /// (Diagnosis::one_half), is judged with the flights as the two halves: each flight's held-out
  /// lines scored with the model fitted with its slow terms sized on the other flights' lines
  /// (loop_steps::across_flights). Kept, the flights stay the halves for the rest of the loop. A
  /// channel that moves on the same survey line of every flight, which each flight's halves put
  /// on one side, is then confirmed by the flights together (false: each flight's halves only).
  bool across_flights = true;
  /// diagnose_loop: when no term passes, each kept term of a recorded channel or of the Earth's
  /// field alone (an eddy decay of B; not the lag) is taken out in turn and the model without it
  /// diagnosed; the best of that diagnosis's first candidates takes
  /// its place when it lowers the held-out error by the accepted share and the resolution and
  /// raises neither half, and the loop goes on (LoopRound::replaced). A term chosen while other
  /// effects were still in the residual is chosen again once they are written (false: a kept
  /// term stays unless later terms make it redundant).
  bool exchange_terms = true;
  /// diagnose_loop over one flight without a validation flight: as the loop ends, a
  /// kept drift (a low-pass of 30 s or slower) of recorded states no other kept term reads leaves
  /// when, with every other term in place, it explains no more of the held-out variance than the
  /// search finds with those states read shifted in time by a quarter, a half and three quarters
  /// of the flight, by a margin, and the model without it leaves no more on the held-out lines
  /// than the loop's start model (loop_steps::Round::drop_chance_slow_term). What the model took
  /// in with it or after it (another term, TL's exact norm) leaves too where the held-out lines
  /// do better without it (loop_steps::Round::shed_after_chance_drift). The loop stops
  /// there ("structure remains: X taken out: a drift this flight cannot tell from chance …"). Over
  /// one flight, a trend of minutes matches another by chance, and the search tries thousands
  /// (false: the held-out halves alone decide).
  bool chance_control = true;
  /// diagnose_loop: before a round keeps its first single term, the runner-up of other channels
  /// (the next that passes alone, leaving at most loop_steps::kLookAheadRatio times the first's
  /// held-out error) is looked at one round ahead: each of the two is fitted, the model with it
  /// diagnosed again, and the best of its first terms that then pass added. When the runner-up's
  /// two rounds lower the first's two rounds' held-out error by the accepted share and the
  /// resolution and raise neither half, the runner-up is kept (the round's refusals say why).
  /// One term may stand in for several effects at once (a field decay for a scalar lag plus an
  /// inductive pick-up) and win its round, while the term of one of them wins the next two
  /// (loop_steps::Round::looking_ahead; false: the round's first term that passes is kept).
  bool look_ahead = true;
  /// diagnose_loop: when no term passes while the residual stays predictable, before a learned
  /// law of it, the recorded state of the aircraft that predicts most of the residual
  /// (ExplainableShare::channels) is tried as its plain field term (`field:X`) with the whole
  /// model fitted again, at the model's ridge strength and with the ridge weakened as
  /// choose_lambda weakens it, and the better kept if it lowers the held-out error by
  /// accept_fraction of its variance and resolution_nT and raises neither half (once per
  /// channel). The search scores each candidate beside TL's exact-norm column as the base's
  /// coefficients left it, at the model's ridge; a channel whose field those coefficients
  /// partly took ranks low there however much it explains once TL is fitted again with it
  /// (loop_steps::Round::named_channel_term; false: the learned law is the only try of that
  /// channel).
  bool named_channel_term = true;
  /// diagnose_loop: when no term passes, before any exchange, the kept terms' parameters (a
  /// step's threshold, a time constant, a saturation level, a delay) are estimated again with
  /// every other term of the model in place: each term's alone, and all of them beside each of
  /// the diagnosis's first three candidates (of distinct channels, whatever their share alone).
  /// The best takes the old terms' place when it lowers the held-out error by the accepted share
  /// and the resolution and raises neither half (LoopRound::replaced). A threshold estimated
  /// while another effect was still in the residual, or at another ridge strength, and a time
  /// constant that stood in for a lag not yet written, are estimated where the model no longer
  /// biases them; a slow term's time constant (a heater's, a drift's) by the error on the
  /// calibration rows the slow stage sizes it on (false: a kept term keeps the parameters it was
  /// added with).
  bool refine_parameters = true;
  /// diagnose_loop, with refine_parameters: a kept step's threshold is placed again where the
  /// held-out lines cross it. The model without the step, diagnosed again with
  /// thresholds_on_selection, ranks the same switch with the threshold its selection lines pin
  /// where the calibration rows cannot tell the thresholds apart (a relay's control may cross its
  /// threshold a few times on the calibration segments and many times on the survey lines); it
  /// takes the kept step's place when the held-out error falls by accept_fraction of its
  /// variance and neither half rises (the resolution is not asked: the change adds no channel,
  /// and its gain sits in the few samples between the two thresholds). False: the calibration
  /// rows alone place it.
  bool place_thresholds_again = true;
  /// diagnose_loop: when no term passes and neither the parameters estimated again nor an
  /// exchange change the model, and once more when the rounds are spent, a kept
  /// product of recorded channels whose factor earns no place (the product does not beat the
  /// same term without it by accepted_fraction of the held-out variance and resolution_nT, nor
  /// by half that variance with each half lowered by accepted_fraction of its own: a current
  /// times a bus the flights hold steady, or times a channel that only rescales it) is
  /// written without that factor, if the simpler term still passes a new term's checks against
  /// the model without either (LoopRound::replaced). The model then names the channels the
  /// flights show (false: a product stays as it was added).
  bool drop_idle_factors = true;
  /// diagnose_loop: when no term passes and nothing else changes the model (and once more when
  /// the rounds are spent), a kept field term of one recorded channel is written as its product
  /// with a channel the rounds listed as one it may scale with unseen (LoopRound::steady_factors:
  /// a bus voltage, the engine speed) or a recorded state held within 10 % of its mean, when the
  /// product raises neither half and its factor earns its place as drop_idle_factors keeps one
  /// (loop_steps::Round::steady_factor_in_place, factor_resolved). False: such a factor is only
  /// reported.
  bool steady_factor_products = true;
  /// diagnose_loop: after a single term is kept, the eligible terms of other channels that it
  /// does not beat are listed as its look-alikes; the best of them that beats it by
  /// accept_fraction of the held-out variance and resolution_nT takes its
  /// place (the screen ranks on the selection lines; the held-out lines decide which of two
  /// channels that move together carries the effect). And when no term passes (or the rounds
  /// are spent), a kept term gives way to a look-alike that leaves a lower held-out error with
  /// every other term in place (loop_steps::Round::better_look_alike_in_place). False: the first
  /// term that passes stays.
  bool better_look_alike = true;
  /// With better_look_alike: a kept slow term (Model::slow_terms: a heater, a drift, a trend
  /// sized by the slow stage) gives way to a look-alike too, the look-alike sized as a slow term
  /// where it was. A drift's stand-in that follows it on one flight (a battery voltage that
  /// charges over the flight) is replaced by the drift's own channel where that does better
  /// with every other term in place (false: slow terms keep the channel their round chose).
  bool slow_look_alikes = true;
  /// When nothing else passes: a kept term that another kept term makes redundant once that
  /// term's parameters are estimated again without it leaves
  /// (loop_steps::Round::redundant_once_refined).
  bool redundant_once_refined = true;
  /// diagnose_loop's backward pass: an earlier round's term leaves when the model without it
  /// loses less than a term must gain to be added (accept_fraction of the held-out variance, or
  /// resolution_nT of its std; and on the validation flight, accept_fraction), so long as the
  /// round still lowers the error of the round before it (false: it leaves only when it explains
  /// under a quarter of accept_fraction).
  bool backward_at_acceptance = true;
  /// diagnose_loop: the backward pass also follows each change that revisits the kept terms
  /// (parameters estimated again, an exchange, a factor dropped, a look-alike swapped in) and the
  /// changes made once the rounds are spent: a term the changed model makes redundant leaves
  /// there too. False: only after a round that adds a term.
  bool backward_after_revisits = true;
  /// diagnose_loop: a change that adds a term of a recorded channel must also hold without the
  /// held-out line where it gains most: on the other lines it lowers the error variance by
  /// accept_fraction (a clock's step or a slowly stepping state that fits one line's wander
  /// gains on one or two lines; an effect gains wherever its channel moves). False (the
  /// default): the held-out lines are judged pooled. `scripts/bench_discovery … line-jackknife`.
  bool line_jackknife = false;
  /// The channels a trained network leans on, as its attribution ranks them (empty: none). The
  /// leading ones (kNetworkChannels with kNetworkMinShare or more) are searched even where the
  /// search would leave them out (full_search false), their products with each other and with
  /// the strongest sources are fitted, and Diagnosis::network says what became of each. Their
  /// terms pass the same acceptance rule as every other: the network offers, the held-out lines
  /// decide.
  std::vector<NetworkChannel> network_channels;
};

/// A set of candidate terms chosen together (diagnose's joint selection). The pool: the round's
/// candidates fitted by the band-pass, kJointPool in rank order, at most two per channel and of
/// at most kJointMaxComplexity (a channel through one transform, or a product of two: a grown
/// chain is one effect's refinement, which the one-at-a-time search judges alone); and the plain
/// term of each of the three channels the remaining residual follows most. Every subset of up to
/// kJointMaxTerms of them, one term per channel, is fitted with the model's columns on the fit
/// rows and scored on the held-out lines. A set answers a look-alike: the first ranked candidate
/// (the lead, accepted alone, which the one-at-a-time search would take first) standing for
/// effects of other channels. A set of two or more terms is admissible when it leaves out the
/// lead, beats it on each half of the held-out lines by the accepted share of the error variance
/// and the resolution, lowers each half's error against the model by the same, and each of its
/// terms is needed (without it, each half's error rises by the same). The admissible set with
/// the lowest held-out error is chosen (within the accepted share of it, the fewest and simplest
/// terms), and kept only if the same set is chosen again in at least kJointStability of
/// kJointResamples bootstrap resamplings of each half's lines. None when no candidate is
/// accepted (pairs that act together are the loop's pair step's) or the lead is not in the pool
/// (a slow term, the lag: left to the one-at-a-time search).
struct JointSet {
  std::vector<TermSpec> terms;  ///< empty: no set is chosen
  double selection_std_nT = NAN, confirmation_std_nT = NAN, heldout_std_nT = NAN;
  /// Each term alone (with the model), held-out error std, nT (in the order of `terms`).
  std::vector<double> alone_std_nT;
  /// The lead it replaces and its held-out error std, nT.
  std::string best_single;
  double best_single_std_nT = NAN;
  /// The share of the resamplings that choose the same set (0..1).
  double stability = 0.0;
  int pool_size = 0;  ///< terms in the pool
};
constexpr size_t kJointPool = 8;
constexpr size_t kJointMaxTerms = 3;
constexpr int kJointMaxComplexity = 3;  ///< term_complexity
constexpr int kJointResamples = 20;
constexpr double kJointStability = 0.6;

struct Diagnosis {
  double baseline_std_nT = 0.0;  ///< held-out error std of the model refitted as it is
  double baseline_selection_std_nT = 0.0;
  double baseline_confirmation_std_nT = 0.0;
  Eigen::Index heldout_samples = 0;
  Eigen::Index fit_samples = 0;
  std::string split;                       ///< how fit, selection and confirmation were chosen
  std::vector<double> selection_lines;     ///< held-out lines the candidates are ranked on
  std::vector<double> confirmation_lines;  ///< held-out lines that confirm (or reject) them
  /// Each sample's part of the split: 0 selection, 1 confirmation, -1 not held out (a line flown
  /// in pieces may hold pieces of both halves; its number is then in both lists above).
  std::vector<signed char> heldout_fold;
  std::vector<Candidate> candidates;             ///< accepted first (best first), then the rejected
  long candidates_tried = 0;                     ///< terms fitted, parameter scans included
  std::vector<ChannelAssociation> associations;  ///< strongest |Spearman| first
  ExplainableShare explainable;                  ///< what remains predictable, and where
  ResidualFloor
      floor;  ///< the held-out residual against its own noise floor; what its power follows
  /// The terms chosen together (DiagnoseOptions::joint_selection); no terms when none.
  JointSet joint;
  /// Each leading channel of DiagnoseOptions::network_channels, in the network's order.
  std::vector<NetworkCheck> network;
  /// A candidate this flight's held-out lines cannot confirm: its channel moves on one half's
  /// lines alone (one_half_term.h); the verdict says so. No term when none.
  OneHalfTerm one_half;
  std::string verdict;             ///< "add <term>", "structure remains", "complete"
  std::vector<std::string> notes;  ///< skipped channels and why
};

/// The data fields diagnose uses as sources: every non-constant, mostly finite field except the
/// bookkeeping ones (tt, line, flight, year, doy), the magnetometers, the fluxgates, `truth`, and
/// the channels that record a constant and their white noise only (records_noise_only: a
/// regulated rail), which `notes` lists.
/// With `rails`, those channels are returned there (and the note says how they are searched).
std::vector<std::string> source_fields(const Model& model, const FlightData& data,
                                       const std::string& truth, bool full_search,
                                       std::vector<std::string>* notes,
                                       std::vector<std::string>* rails = nullptr);

/// The share of the held-out variance, on each split, a term reading a rail (a channel that
/// records a constant and its white noise only) must explain to stay a candidate: its low-passed
/// values are a random walk that follows a slow residual's wander by chance for a few percent,
/// never for most of it; an effect that the rail's recorded wander drives is most of what TL
/// leaves where it is large enough to matter.
constexpr double kRailShare = 0.25;

/// The leading channels of a network's attribution (DiagnoseOptions::network_channels): sorted
/// by share, the first kNetworkChannels with at least kNetworkMinShare.
std::vector<NetworkChannel> network_leads(std::vector<NetworkChannel> ranked);

/// The data channels a term reads (not B or Bt; none for a TL family).
std::vector<std::string> term_channels(const TermSpec& term);

/// How much a term says: its sources, transforms and their parameters (a shorthand or TL
/// family counts 1). Between terms that explain as much, the simpler is preferred.
int term_complexity(const TermSpec& term);

/// The longest time constant of the low-passes in a term's chain, s (0 without one).
double slowest_low_pass_s(const TermSpec& term);

/// Moves to the front the simplest of the ranked items (each with a `term`) that tie with the
/// first: the leading run of items for which tied(first, item) holds.
template <typename T, typename Tied>
void put_simplest_first(std::vector<T>* ranked, Tied tied) {
  if (ranked->empty()) return;
  size_t pick = 0;
  for (size_t k = 1; k < ranked->size(); ++k) {
    if (!tied(ranked->front(), (*ranked)[k])) break;
    if (term_complexity((*ranked)[k].term) < term_complexity((*ranked)[pick].term)) pick = k;
  }
  std::rotate(ranked->begin(), ranked->begin() + static_cast<long>(pick),
              ranked->begin() + static_cast<long>(pick) + 1);
}

/// Ranks candidate terms for what the model misses. Fit rows: the model's own calibration
/// (band-pass segments, or reference-fit lines) when this flight holds them; otherwise a
/// reference fit against `truth` on every other line. The other lines are held out and split,
/// line by line in time order, into selection and confirmation lines. Throws magcomp::Error
/// naming the file and field on bad input.
Diagnosis diagnose(const Model& model, const FlightData& data, const std::string& truth,
                   const DiagnoseOptions& options = {});

}  // namespace magcomp
