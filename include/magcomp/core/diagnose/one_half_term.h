// magcomp: a candidate the held-out lines cannot confirm: it explains most of one half's error
// while its channel moves on that half's lines alone (a flap run out on one survey line), so the
// other half neither confirms nor refutes it and one flight cannot decide.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <string>
#include <vector>

namespace magcomp {

/// The first ranked candidate, not accepted, that explains kOneHalfShare or more of one half's
/// held-out variance while a channel it reads moves on none of the other half's units.
struct OneHalfTerm {
  std::string term;           ///< the candidate (TermSpec text); empty when there is none
  std::string channel;        ///< its channel that is idle on the other half
  int half = -1;              ///< where the channel moves: 0 selection, 1 confirmation lines
  double explained = NAN;     ///< share of that half's held-out variance the term explains
  std::vector<double> lines;  ///< the held-out lines on which the channel moves, ascending
};

/// The share of one half's held-out variance a candidate must explain to be named so.
constexpr double kOneHalfShare = 0.5;
/// A channel moves on a held-out unit (a line, or a piece of a line flown in pieces) when its
/// std there exceeds this many times the median of its std over the held-out units.
constexpr double kMovesFactor = 3.0;

/// The held-out units (0 .. units-1) on which `channel` (one value per sample) moves: its std on
/// the unit's samples (`unit[i]`: the sample's unit, -1 when not held out; NaN samples skipped)
/// above kMovesFactor times the median of the units' stds. Empty when it moves on all alike.
std::vector<int> moving_units(const Eigen::VectorXd& channel, const std::vector<int>& unit,
                              int units);

/// The clause the verdict adds for `t` ("" when t.term is empty): what it explains where, the
/// lines its channel moves on, and that a second flight of the aircraft can confirm it.
std::string one_half_clause(const OneHalfTerm& t);

}  // namespace magcomp
