// magcomp: how well a flight supports each term a diagnosis added: how often its channel moved
// where the coefficients were fitted, and how uncertain the term's size is.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "magcomp/core/diagnose/channel_twins.h"
#include "magcomp/core/diagnose/time_trend.h"
#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/model/model.h"

namespace magcomp {

/// One added term's support on the flight it was fitted on.
struct TermSupport {
  std::string term;     ///< the term's spec
  std::string channel;  ///< its first source channel ("" for a term without one)
  /// Times the channel crossed, on the fit rows, between the lower and upper quarter of its
  /// 1-99 % range over the whole flight (one switch on and off counts two; a channel idle on the
  /// fit rows does not switch there, whatever its noise); -1 without a channel.
  int switches = -1;
  /// Sized by the slow stage on the calibration rows and the lines beside them
  /// (Model::slow_terms with fit.slow_lines): its switches are counted on those rows too.
  bool on_lines = false;
  /// 1-sigma uncertainty of the term's contribution to the compensated field, nT: the rms over
  /// the flight's rows of sqrt(a_i' Σ a_i), with a_i the term's columns beyond the model's other
  /// columns (as for size_nT) and Σ their block of the
  /// coefficients' covariance by the jackknife over 20 blocks of the calibration rows
  /// (coefficient_jackknife_covariance; the fit's own covariance when the rows are too few). NaN
  /// when neither is known, and for a term of the slow stage.
  double size_sigma_nT = NAN;
  /// The term's contribution's std over the flight, nT (its size), counting only what the model's
  /// other columns and a constant cannot take: its columns less their least-squares fit by those
  /// over the flight's rows. A field term of a channel that holds a level (a bus voltage) is
  /// mostly that level times the permanent columns; its size is what it adds to them.
  double size_nT = NAN;
  /// Each recorded channel of the term with the channels the flights cannot tell it from
  /// (channel_twins), in the order of the term's sources: the term names one of each set.
  std::vector<ChannelTwin> twins;
  /// Each recorded channel of the term that follows a smooth curve of time on every flight
  /// (time_trend: a charging battery, a warm-up), in the order of the term's sources. A term of
  /// it writes any effect of that shape; the flights cannot say that this channel carries it.
  std::vector<TimeTrend> time_trends;
  /// When the term's longest low-pass sits at the longest time constant the flights tell apart
  /// (within 1 % of the top of parameter_grid's low-pass scan for the longest flight: a third of
  /// it, at most 3000 s): that time constant, s. The flights cannot tell the term's response from a
  /// slower one, so the term stands for a drift that any slow channel may match. NaN otherwise.
  double slowest_time_constant_s = NAN;
};

/// The support of each term of the fitted `model` that `start` does not have, on `data` (the
/// flight the model was fitted on; its fit rows are model.fit's lines and windows, every row
/// when it names none).
std::vector<TermSupport> term_support(const Model& model, const Model& start,
                                      const FlightData& data);

/// The same over several flights the model was fitted on together: the switches summed over
/// their fit rows, the size and its uncertainty over all their rows.
std::vector<TermSupport> term_support(const Model& model, const Model& start,
                                      const std::vector<const FlightData*>& flights);

/// The words a user reads: "cur_X switched 2 times on the calibration rows: its size, 3.1 nT, is
/// uncertain to ±0.8 nT" when it switched fewer than `few_switches` times; "its size, 17.4 nT,
/// is not determined by the calibration rows (±10 nT over blocks of them): X may stand in for
/// another effect" when the size lies within two sigma of none; else "". `rows` names the rows
/// that size it (for a term sized on the lines too, TermSupport::on_lines, those rows are named).
std::string support_note(const TermSupport& s, int few_switches = 10,
                         const std::string& rows = "the calibration rows");

/// The words a user reads of a term whose channel has twins (TermSupport::twins): "these flights
/// cannot tell vol_acpwr from vol_outpwr (r 0.99956), smoothed over 5 s: the effect may be
/// either's"; "" without twins.
std::string twins_note(const TermSupport& s);

/// The words a user reads of a term whose channel follows the flights' time
/// (TermSupport::time_trends): "cur_bat_2 follows a smooth curve of time on these flights (a
/// cubic in time gives 99.9 % of the variance of its 5 s means): a term of it writes any effect
/// of that shape (a charge, a warm-up, another source's drift), and these flights cannot say
/// that cur_bat_2 carries it; a flight on which it runs another course tells"; "" otherwise.
std::string time_trend_note(const TermSupport& s);

/// The words a user reads of a term at the longest time constant the flights tell apart
/// (TermSupport::slowest_time_constant_s): "its time constant is the longest these flights tell
/// apart (665 s): it stands for a drift at least that slow, which a slow trend of any channel may
/// match as well as X's; a second flight (--validate NEXT.h5) tells whether X carries it"; ""
/// otherwise.
std::string slow_edge_note(const TermSupport& s);

/// Times a channel's samples x (its unit) crossed, on `rows` (in time order), between the lower
/// and upper quarter of its 1-99 % range over all of x (one switch on and off counts two; a
/// channel idle on the rows, its noise only, does not switch there). 0 when x barely varies.
int channel_switches(const Eigen::VectorXd& x, const std::vector<Eigen::Index>& rows);

/// Columns [from, from + n) of `a` (N x p) less their least-squares fit by the other columns and
/// a constant over the rows where every column is finite (NaN on the other rows): the part of a
/// term the model's other columns cannot take. A field term of a channel that holds a level is
/// mostly that level times the permanent columns; its size is what it adds to them.
Eigen::MatrixXd beyond_other_columns(const Eigen::MatrixXd& a, Eigen::Index from, Eigen::Index n);

}  // namespace magcomp
