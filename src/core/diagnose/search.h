// magcomp: diagnose's search, step by step (internal to src/core/diagnose): the jobs a round
// tries, the Search every candidate is scored against, the candidates they become, the grammar
// growth and the product screen, the judging and ranking, the floor and the verdict. diagnose()
// (diagnose.cpp) runs them in that order.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "magcomp/core/diagnose/diagnose.h"
#include "magcomp/core/diagnose/explainable_share.h"
#include "magcomp/core/diagnose/residual_floor.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/fit/parameter_fit.h"
#include "magcomp/core/fit/slow_stage.h"
#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/math/timeseries.h"
#include "magcomp/core/model/model.h"
#include "magcomp/core/model/term.h"
#include "magcomp/core/model/term_spec.h"

namespace magcomp::diagnose_search {

// --- jobs and their scores (candidates.cpp) ---

bool is_current(const std::string& n);
bool is_rate(const std::string& n);
// The shorthand a plain source is written with: current:X, rate:X, or field:X.
std::string plain_spec(const std::string& x);
// The TL family a term belongs to (permanent, induced, eddy), else the term itself.
std::string family_of_tl(const std::string& spec);

// One term to try: the term (free parameters as ?), what kind of effect, which channel.
struct Job {
  TermSpec term;
  std::string family;
  std::string channel;
};

// Result of one job.
struct Scored {
  bool ok = false;
  TermPtr term;  // parameters as numbers (null for the lag, scored before its value is a term)
  double sel = 0, conf = 0, held = 0;
  Eigen::VectorXd coef;  // the candidate's coefficients
  long fits = 0;
  std::string note;
  bool slow = false;  // fitted by the slow stage (Model::slow_terms), not the band-pass
  // The share of the columns' energy on the fit rows that lies in the span of the base's
  // columns there (NaN when fitted by the slow stage).
  double base_span_share = NAN;
};

// A column whose band-passed energy on the calibration segments is below this share of its
// energy there (segment means removed) is one the band-pass barely sees: it is also fitted by
// the slow stage, and the better of the two on the selection lines is kept.
constexpr double kSlowBandFraction = 0.01;
// The slowest low-pass of a motion channel (is_motion_channel) a candidate may take, s: a
// structure's flex or a tank's slosh answers a rate or an acceleration within seconds; a slower
// low-pass of motion integrates the trajectory (heading, position), where map and diurnal
// leakage hide, and would stand in for a state's slow effect that turns follow.
constexpr double kMaxMotionLowPass_s = 20.0;

// A step whose control crosses its threshold once over the flight is a step in time (a
// battery's charge current decaying through it): its on/off state, each sample replaced by the
// majority within kClockWindow_s either side (a switch shorter than that, and the noise's chatter
// where a slow channel crosses the threshold, leave no mark), changes once, with at least
// kClockWindow_s on either side. Such a step fits whatever changed at that moment -- the map's
// level between segments, a drift, the diurnal -- and no relay's field: it is not a candidate
// (step_in_time).
constexpr double kClockWindow_s = 30.0;
// The least share of a step's samples a single switch in time must agree with (on before it and
// off after, or the other way) for the step to be one in time: a relay chattering on its
// control's noise all through the flight agrees with none much beyond its commoner state's
// share. On the benchmark's flights (runs 101-173) the steps whose majority alone reads as one
// switch agree with 0.53 to 0.79 (currents idling within their noise, the flaps, the engine
// speed, a heater switched through the flight), a slow channel crossing once with 0.87 to 0.99
// (an outside air temperature, a battery's charge current).
constexpr double kClockAgreement = 0.8;
// Whether `signal`'s step at `threshold` (the first transform of its chain; samples of the
// sources' product above it on) switches once in time over `data`'s rows (kClockWindow_s; the
// rows 0.1 s apart where `data` has no time column "tt").
bool step_in_time(const SignalExpr& signal, double threshold, const FlightData& data);

// The integral of a current that never reverses (a load's current, the charge it has drawn)
// rises through the flight: its net change is at least this share of its range. Such an
// integral measures how long the load has run, a clock that fits whatever drifted, and reaches
// other levels on another flight; it is not a candidate (integral_in_time). A current that
// reverses (a motor driven both ways) integrates to a position, back and forth within its range.
constexpr double kClockIntegralShare = 0.9;

// Whether `signal` holds an integral (TransformKind::Integral) whose value on `data`, the
// transforms up to it applied to the sources' product, changes over the flight by
// kClockIntegralShare of its range or more. False without an integral or without `tt`.
bool integral_in_time(const SignalExpr& signal, const FlightData& data);

// A step's threshold, scanned on the calibration rows, can fall anywhere within the thresholds
// those rows cannot tell apart, while the held-out lines cross it many times more (a relay whose
// control dwells near its threshold on the survey lines and sweeps through it on the maneuvers):
// the calibration rows' residual sum of squares within kThresholdTieChi2 times its per-row
// variance of the best (the 95 % profile-likelihood interval of one parameter), searched over
// at most kThresholdTiePieces of their pieces each side, bounds the thresholds the selection
// lines then choose among (Search::threshold_on_selection), kThresholdProbes at a time, coarse
// to fine. Only for a step that explains kThresholdRefineShare of the selection lines' variance.
constexpr double kThresholdTieChi2 = 3.84;
constexpr long kThresholdTiePieces = 64;
constexpr size_t kThresholdProbes = 17;
constexpr double kThresholdRefineShare = 0.02;

// A held-out half is quiet when its error is under this many resolutions: gaining the
// resolution there takes more than half of its variance. A candidate may then remove
// kQuietHalfShare of that half's variance in place of the resolution, when all held-out lines
// together gain the resolution (judge.cpp): a drift that lives in the pieces of a long line and
// barely within the other half's short survey lines.
// Not for a term whose fit-row columns lie within the base's span by kQuietHalfMaxSpanShare of
// their energy or more (Scored::base_span_share).
constexpr double kQuietHalfResolutions = 3.0;
constexpr double kQuietHalfShare = 0.25;
constexpr double kQuietHalfMaxSpanShare = 0.99;

// --- the search (search.cpp; the lag's part in search_lag.cpp) ---

// Mean-removed RMS per line over the rows of one fold (-1: every held-out row); NaN when fewer
// than 90 % of the fold's rows have a finite error.
double fold_std(const Eigen::VectorXd& e, const std::vector<Eigen::Index>& held,
                const std::vector<int>& fold, const Eigen::VectorXd& line, int which);

// Everything a candidate is scored against: read-only once built, shared by the workers.
class Search {
 public:
  // With `slow_on_lines`, a slow candidate is sized on the held-out lines too, cross-fitted
  // (score_slow); the base's own slow terms are fitted as fit_model fits them (fit.slow_lines).
  // With `thresholds_on_selection`, a step's threshold is moved within the calibration rows'
  // tie interval by the selection lines (threshold_on_selection). With `second_order_on_lines`
  // and `slow_on_lines`, TL's second-order term is sized on the lines too (score_slow).
  Search(const Model& model, const FlightData& data, const std::string& truth_name, Diagnosis* dx,
         bool slow_on_lines = false, bool thresholds_on_selection = false,
         bool second_order_on_lines = false);

  // Scores a term's columns (N x k): fit on the fit rows with the base columns, errors on the
  // held-out rows of each fold. With `slow_ok`, a column the band-pass barely sees
  // (kSlowBandFraction) is also scored by the slow stage; the better on the selection lines is
  // returned.
  Scored score(const Eigen::MatrixXd& cols, bool slow_ok = false) const;
  // Scores columns fitted by the slow stage: to the base error on the calibration rows,
  // unfiltered, each segment's mean removed. Sized on the held-out lines too (slow_on_lines):
  // each half's error is that of the size fitted on the calibration rows and the other half's
  // lines, so that neither half scores a size it was fitted on.
  // The base's coefficients take their share of the columns' band content (band_share); the
  // fitted model gives it back (fit_model), and so does each size here.
  // `band` (optional): the columns as stacked for the fit (band()), when already at hand.
  Scored score_slow(const Eigen::MatrixXd& cols, const Eigen::MatrixXd* band = nullptr) const;
  // The base's band-pass coefficients' share of columns (N x k): the ridge fit of their stacked
  // band content on the base's (af0), p x k, per unit of column. The field of a bus at its
  // steady level is that level times the direction cosines: the permanent terms' share.
  Eigen::MatrixXd band_share(const Eigen::MatrixXd& cols) const;
  // The slow stage's residual sum of squares with these columns (nT²), on the calibration rows
  // (and the selection lines with slow_on_lines).
  double slow_rss(const Eigen::MatrixXd& cols) const;
  // Whether the slow stage exists here: a band-pass fit on this flight's calibration segments.
  bool has_slow_stage() const { return slow_stage != nullptr; }
  // Whether slow candidates are sized on the held-out lines too, cross-fitted: each half's
  // error read with the size from the calibration rows and the other half's lines.
  bool slow_cross_fitted() const { return slow_cross[0] != nullptr; }
  // Each column's mean over the held-out rows (its finite values; 0 where it has none), in the
  // columns' units.
  Eigen::RowVectorXd held_mean(const Eigen::MatrixXd& cols) const;
  // On the held-out rows (0 elsewhere), N: x (N x m, NaN read as 0) times within (m x k, the
  // columns' share, band_share) times size (k): what a slow size gives back through the base's
  // coefficients, nT. Zero when within is empty.
  Eigen::VectorXd held_product(const Eigen::MatrixXd& x, const Eigen::MatrixXd& within,
                               const Eigen::VectorXd& size) const;
  // The share (0..1) of the energy of stacked fit-row columns (M x k) that lies in the span of
  // the base's fittable columns on those rows (af0).
  double base_span_share(const Eigen::MatrixXd& band) const;
  // The fit's residual sum of squares with these columns added.
  double fit_rss(const Eigen::MatrixXd& cols) const;
  // A step's threshold (in its signal's unit), scanned on the calibration rows, moved to the
  // threshold within the calibration rows' tie interval (kThresholdTieChi2) whose columns give
  // the selection lines the lowest error, when that is below selection_nT (the selection lines'
  // error at `threshold`, nT); written as scan_threshold() writes it. `values`: the signal's
  // values on the flight, sorted (signal_values_sorted). Adds the fits it makes to *fits.
  double threshold_on_selection(const ExprTerm& expr, const std::vector<double>& values,
                                double threshold, double selection_nT, bool slow_ok,
                                long* fits) const;
  // Builds, scans (free parameters) and scores one job.
  Scored run(const Job& job) const;
  // The lag scan, alone or with partner columns (N x k, built without a lag: columns_of(spec,
  // false)): each trial realigns the scalar by tau and gives every column tau's round trip.
  Scored lag_candidate(double* tau_out, const Eigen::MatrixXd& partner) const;
  // The lag fixed at tau (s), with partner columns (built without a lag).
  Scored lag_at(double tau, const Eigen::MatrixXd& partner) const;
  // Columns (N x k) as the fit reads them: each calibration run band-passed and trimmed (or as
  // they are for a reference fit), stacked; NaN read as 0.
  Eigen::MatrixXd band(const Eigen::MatrixXd& cols) const { return stacked(cols); }
  // The columns of a term on this flight, N x k; with `with_lag`, carrying the model's lag
  // round trip as the base columns do (design_matrix).
  Eigen::MatrixXd columns_of(const Term& t, bool with_lag = true) const {
    Eigen::MatrixXd c(data.size(), t.columns());
    t.build(inputs, c);
    if (with_lag) lag_round_trip(c, model.scalar_lag_s() / dt);
    return c;
  }

  const Model& model;
  const FlightData& data;
  Eigen::VectorXd scalar, truth, line;
  FitSettings fs;
  std::vector<std::pair<Eigen::Index, Eigen::Index>> runs;
  std::vector<Eigen::Index> held;
  std::vector<int> fold;  // per sample: 0 selection, 1 confirmation, -1 not held out
  std::vector<int> unit;  // per sample: its held-out unit, in time order (-1: not held out)
  TermInputs inputs;
  Eigen::MatrixXd a0;  // the base's fittable columns, N x p
  Eigen::MatrixXd af0;
  Eigen::MatrixXd af0_basis;  // an orthonormal basis of af0's column span, M x rank
  Eigen::VectorXd yf;
  std::unique_ptr<RidgeProfile> profile;
  Eigen::VectorXd e0;                     // base error, N
  Eigen::VectorXd slow0;                  // the base's slow-stage correction (Model::slow_terms), N
  Eigen::MatrixXd band_inv;               // (af0' af0 + lambda)^-1, p x p
  std::shared_ptr<SlowStage> slow_stage;  // a candidate's slow fit (a reference fit: on the lines)
  // With slow_on_lines: the slow fit on the calibration rows and the lines of half h (0:
  // selection, 1: confirmation), which sizes the other half's error; slow_stage is the first.
  std::shared_ptr<SlowStage> slow_cross[2];
  // The runs slow_stage is fitted on (first, last rows), and the base's slow columns it is
  // fitted beside with a0 (N x s; no column when the base has no slow term).
  std::vector<std::pair<Eigen::Index, Eigen::Index>> slow_runs;
  Eigen::MatrixXd slow_base_cols;
  double base_std[3] = {0, 0, 0};  // selection, confirmation, all held out
  double dt = 0.1, span = 1.0;
  bool pin_thresholds = false;     // threshold_on_selection for every step candidate
  bool second_order_slow = false;  // second_order also sized on the lines (slow_cross)

 private:
  Eigen::MatrixXd stacked(const Eigen::MatrixXd& cols) const {
    const Eigen::MatrixXd z = cols.unaryExpr([](double v) { return std::isfinite(v) ? v : 0.0; });
    return stack_runs(fs, dt, z, runs);
  }
  // stacked() of the columns given a lag's round trip of tau s (only the fit rows are built).
  Eigen::MatrixXd stacked_at_lag(const Eigen::MatrixXd& cols, double tau) const;
  // The base's fittable columns without the model's lag round trip, then `partner`: N x (p + k).
  Eigen::MatrixXd lag_columns(const Eigen::MatrixXd& partner) const;
  // The fit of lag_columns() `x` with a lag of tau s: the stacked fit rows' residual sum of
  // squares, and the coefficients in `coef`.
  double lag_fit(double tau, const Eigen::MatrixXd& x, Eigen::VectorXd* coef) const;
  // lag_at() with lag_columns() `x` of which the last `partners` are the partner's.
  Scored lag_scored(double tau, Eigen::MatrixXd x, Eigen::Index partners) const;
};

// The share of the variance a candidate removes: 1 - (after / before)^2 (0 without a before).
double share(double after, double before);

// --- the steps of a round ---

// Candidate jobs for the sources and the model (candidates.cpp). A source in `rate_recorded`
// (recorded_rates: another source records its rate of change) has no rate-of-change term: the
// recorded rate's own terms name that effect.
std::vector<Job> make_jobs(const Model& model, const std::vector<std::string>& sources,
                           const std::set<std::string>& rate_recorded = {});
// Runs jobs on `threads` workers (candidates.cpp).
std::vector<Scored> run_jobs(const Search& search, const std::vector<Job>& jobs, int threads);
// Products of the strongest sources (candidates.cpp).
std::vector<std::pair<double, std::string>> strongest_sources(const Model& model,
                                                              const Search& search,
                                                              const std::vector<Job>& jobs,
                                                              const std::vector<Scored>& scored);
std::vector<Job> product_jobs(const Model& model, const Search& search,
                              const std::vector<Job>& jobs, const std::vector<Scored>& scored,
                              double accept_fraction);
// Pairs of channels screened cheaply for a product term; the best `keep` become jobs, at most
// kScreenedPerChannel of them reading one channel (products.cpp).
constexpr size_t kScreenedProducts = 12;   // pairs fitted in full after the screen
constexpr size_t kScreenedPerChannel = 3;  // of them, pairs that read one channel
std::vector<Job> screened_products(const Search& search, const std::vector<std::string>& sources,
                                   const std::vector<Job>& taken, size_t keep, int threads);
// A network's leading channels (network_channels.cpp), with `all` the full search's sources
// (source_fields): those the search left out added to the aircraft's sources (not a position
// or an earth-frame velocity, and among `all`); their products with each
// other and with the kNetworkPartners strongest sources, those not already in `taken`; each
// candidate's share of the network's attribution; and what became of each channel.
constexpr size_t kNetworkPartners = 6;
void add_network_sources(const std::vector<std::string>& all,
                         const std::vector<NetworkChannel>& leads,
                         std::vector<std::string>* aircraft_sources);
std::vector<Job> network_product_jobs(const Model& model, const Search& search,
                                      const std::vector<Job>& jobs,
                                      const std::vector<Scored>& scored,
                                      const std::vector<NetworkChannel>& leads,
                                      const std::vector<std::string>& aircraft_sources,
                                      const std::vector<Job>& taken);
void mark_network_share(const std::vector<NetworkChannel>& leads,
                        std::vector<Candidate>* candidates);
std::vector<NetworkCheck> network_checks(const FlightData& data,
                                         const std::vector<std::string>& all,
                                         const std::vector<NetworkChannel>& leads,
                                         const std::vector<Candidate>& candidates,
                                         const std::vector<std::string>& aircraft_sources);
// The grammar growth (grammar.cpp): whether a term's time constant sits at the top of its scan,
// and the children of the best electrical terms.
bool at_slow_edge(const Term& term, const Search& search);
// A chain of one source in `rate_recorded` through low-passes and delays only is not grown into
// its derivative (the recorded rate's chain).
std::vector<Job> refined_jobs(const Model& model, const Search& search,
                              const std::vector<Job>& jobs, const std::vector<Scored>& scored,
                              std::set<std::string>* seen,
                              const std::set<std::string>& rate_recorded = {});
// Every scored job becomes a candidate (candidates.cpp).
void add_candidates(const std::vector<Job>& jobs, const std::vector<Scored>& scored,
                    const Search& search, Diagnosis* dx);
// The scalar lag, alone or with the best channel term (search_lag.cpp).
void add_lag_candidate(const Model& model, const FlightData& data, const Search& search,
                       Diagnosis* dx);
// Acceptance on both halves, then the ranking (judge.cpp).
void judge_and_rank(const Search& search, const DiagnoseOptions& options,
                    std::vector<Candidate>* candidates);
// The terms chosen together from the ranked candidates and the remaining residual's channels
// (joint_selection.cpp; JointSet in diagnose.h).
JointSet joint_selection(const Search& search, const std::vector<Candidate>& candidates,
                         const ExplainableShare& explainable, const DiagnoseOptions& options);
// How well the rows that size a candidate size it (term_uncertainty.cpp): Candidate::size_nT,
// size_sigma_nT (the jackknife over kJackknifeBlocks contiguous blocks of those rows),
// coefficient_sigma and switches. Filled for the first kSizedCandidates accepted candidates (not
// the lag).
constexpr int kJackknifeBlocks = 20;  // as coefficient_jackknife_covariance
constexpr size_t kSizedCandidates = 3;
void size_uncertainty(const Search& search, Candidate* candidate);

// What remains, its floor and the verdict (verdict.cpp).
ExplainableShare remaining_share(const FlightData& data, const Search& search,
                                 const std::vector<std::string>& sources, double baseline_std_nT,
                                 double resolution_nT);
// The first ranked candidate, of the kOneHalfCandidates first not accepted, that explains
// kOneHalfShare of one half's held-out variance (and the resolution) while a channel it reads
// moves on that half's units alone (one_half_term.cpp); OneHalfTerm::term empty when none, or
// when the first candidate is accepted.
constexpr size_t kOneHalfCandidates = 20;
OneHalfTerm one_half_term(const FlightData& data, const Search& search,
                          const std::vector<Candidate>& candidates, double resolution_nT);
ResidualFloor floor_of(const FlightData& data, const Search& search,
                       const std::vector<std::string>& sources);
std::string verdict_of(const Diagnosis& dx, double resolution_nT);

}  // namespace magcomp::diagnose_search
