// magcomp: diagnose's remainder: what predicts it, its noise floor, and the verdict (see
// search.h).
#include <Eigen/Dense>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <future>
#include <iomanip>
#include <map>
#include <set>
#include <sstream>

#include "magcomp/core/diagnose/term_support.h"
#include "magcomp/core/error.h"
#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/model/field_range.h"
#include "magcomp/core/model/terms_expr.h"
#include "search.h"

namespace magcomp::diagnose_search {

// What remains: the base residual on the held-out lines (each line's mean removed) against a
// flexible model of the source channels.
ExplainableShare remaining_share(const FlightData& data, const Search& search,
                                 const std::vector<std::string>& sources, double baseline_std_nT,
                                 double resolution_nT) {
  Eigen::VectorXd r = Eigen::VectorXd::Constant(data.size(), NAN);
  std::map<double, std::pair<double, double>> mean;
  for (Eigen::Index i : search.held) {
    auto& m = mean[search.line[i]];
    m.first += search.e0[i];
    m.second += 1;
  }
  for (Eigen::Index i : search.held) {
    const auto& m = mean[search.line[i]];
    r[i] = search.e0[i] - m.first / m.second;
  }
  std::vector<std::pair<std::string, Eigen::Map<const Eigen::VectorXd>>> channels;
  for (const auto& s : sources) channels.emplace_back(s, data.column(s));
  ExplainableShare x =
      explainable_share(r, search.unit, search.line, data.tt(), search.inputs.direction, channels,
                        [&data] { data.drop_mapped_pages(); });
  // A predictable remainder below the resolution is noise for every practical purpose.
  if (std::sqrt(std::max(0.0, x.share)) * baseline_std_nT < resolution_nT) x.within_noise = true;
  return x;
}

// The base residual's floor and what its power follows, on the held-out samples.
ResidualFloor floor_of(const FlightData& data, const Search& search,
                       const std::vector<std::string>& sources) {
  Eigen::VectorXd r = Eigen::VectorXd::Constant(data.size(), NAN);
  for (Eigen::Index i : search.held) r[i] = search.e0[i];
  std::vector<std::pair<std::string, Eigen::Map<const Eigen::VectorXd>>> channels;
  for (const auto& s : sources) channels.emplace_back(s, data.column(s));
  return residual_floor(r, search.unit, 1.0 / search.dt, channels);
}

// "complete" only while the held-out residual is within this factor of its own noise floor.
constexpr double kCompleteWithinFloor = 1.5;

// What is known of a residual no term explains: how far above its floor, what predicts it,
// whether it follows position (map or trajectory leakage), and what its power follows.
std::string remainder_description(const Diagnosis& dx) {
  const ExplainableShare& x = dx.explainable;
  const ResidualFloor& f = dx.floor;
  std::ostringstream o;
  o.setf(std::ios::fixed);
  o.precision(3);
  o << "the held-out residual is " << f.residual_std_nT << " nT, " << f.residual_std_nT - f.floor_nT
    << " nT above a noise floor of " << f.floor_nT << " nT (its spectrum's white level above "
    << std::setprecision(1) << f.band_lo_hz << " Hz)";
  if (!f.floor_channel.empty()) {
    o << std::setprecision(2) << ", a level that follows " << f.floor_channel
      << " (rank correlation " << f.floor_correlation << "): not the sensor's noise alone";
  }
  const bool predictable = x.computed && !x.within_noise;
  if (predictable) {
    std::vector<std::string> chans;
    bool position = false;
    for (size_t k = 0; k < x.channels.size() && chans.size() < 3; ++k) {
      if (x.channels[k].second <= 0) break;
      chans.push_back(x.channels[k].first);
      if (chans.size() == 1) position = is_position_channel(x.channels[k].first);
    }
    o << std::setprecision(1) << "; " << 100 * x.share << "% +- " << 100 * x.uncertainty
      << "% of it is predictable (noise floor " << 100 * x.noise_floor << "%)";
    if (!chans.empty()) {
      o << ", mostly from ";
      for (size_t k = 0; k < chans.size(); ++k) o << (k ? ", " : "") << chans[k];
    }
    if (position) {
      o << ": it follows position, so it is map or trajectory leakage (the reference fit, IGRF "
           "or diurnal), not an aircraft field";
    } else {
      o << ", and no term of the search explains it";
    }
    if (!x.time_scales.empty()) {
      const auto top =
          std::max_element(x.time_scales.begin(), x.time_scales.end(),
                           [](const auto& a, const auto& b) { return a.second < b.second; });
      o << "; mostly " << top->first;
    }
  } else if (x.computed) {
    o << "; no recorded channel predicts its sign";
  }
  if (!f.amplitude_channel.empty()) {
    o << std::setprecision(2) << "; its amplitude follows " << f.amplitude_channel
      << " (rank correlation of the local variance " << f.amplitude_correlation << ")";
    if (x.computed && !predictable) o << ": its phase is not recorded";
  }
  return o.str();
}

// What the verdict adds of a term the rows that size it barely support: term_support's note on
// it (its channel switched fewer than 10 times there, or its size within two stds of none),
// and where its std is kAdviseSize of its size or more, where a better size comes from. Empty
// otherwise.
constexpr double kAdviseSize = 0.2;
std::string size_caveat(const Candidate& c) {
  if (!std::isfinite(c.size_nT) || !std::isfinite(c.size_sigma_nT)) return "";
  TermSupport s;
  s.term = c.term.text();
  s.channel = c.switches_channel;
  s.switches = c.switches;
  s.size_nT = c.size_nT;
  s.size_sigma_nT = c.size_sigma_nT;
  const std::string note = support_note(s, 10, "the rows that size it");
  if (note.empty()) return "";
  std::string out = "; " + note;
  if (c.size_sigma_nT >= kAdviseSize * c.size_nT)
    out +=
        "; a flight where it switches more, or several flights together (--data A.h5,B.h5), "
        "sizes it";
  return out;
}

namespace {

// The verdict without its one-half clause: add the top term, or complete (within the floor), or
// what remains and where.
std::string verdict_before_one_half(const Diagnosis& dx, double resolution_nT) {
  char buf[512];
  const ExplainableShare& x = dx.explainable;
  if (!dx.candidates.empty() && dx.candidates.front().accepted &&
      dx.candidates.front().explained_fraction >= 0.05) {
    const Candidate& c = dx.candidates.front();
    if (c.chosen_on_confirmation) {
      std::snprintf(buf, sizeof(buf),
                    "add %s: it explains %.1f%% of the held-out error on the confirmation lines "
                    "(where it ranks first) and %.1f%% on the selection lines; the held-out "
                    "error falls from %.3f to %.3f nT",
                    c.term.text().c_str(), 100 * c.explained_confirmation,
                    100 * c.explained_selection, dx.baseline_std_nT, c.std_after_nT);
    } else {
      std::snprintf(buf, sizeof(buf),
                    "add %s: it explains %.1f%% of the held-out error on the selection lines and "
                    "%.1f%% on the confirmation lines",
                    c.term.text().c_str(), 100 * c.explained_selection,
                    100 * c.explained_confirmation);
    }
    std::string out = buf;
    if (within_model_span(c.base_span_share)) {
      std::snprintf(buf, sizeof(buf),
                    "; but %.4f%% of its columns' energy on the fit rows lies within the model's "
                    "own columns: its size there is the ridge's split of its channel's level, "
                    "which another flight reads through it (diagnose --apply tries a weaker "
                    "ridge in its place and never adds it)",
                    100 * c.base_span_share);
      out += buf;
    }
    return out + size_caveat(c);
  }
  const ResidualFloor& f = dx.floor;
  if (f.computed && !f.floor_channel.empty() &&
      f.residual_std_nT <=
          f.floor_nT + std::max(resolution_nT, (kCompleteWithinFloor - 1) * f.floor_nT)) {
    // At its high-frequency level, but that level follows the aircraft: not the sensor's noise.
    std::snprintf(buf, sizeof(buf),
                  "structure remains: the held-out residual (%.3f nT) is near its spectrum's "
                  "white level above %.1f Hz (%.3f nT), but that level follows %s (rank "
                  "correlation %.2f over %d segments): an effect of the aircraft (a relay "
                  "chattering on its channel's noise, a vibration), not the sensor's noise",
                  f.residual_std_nT, f.band_lo_hz, f.floor_nT, f.floor_channel.c_str(),
                  f.floor_correlation, f.segments);
    return buf;
  }
  if (f.computed) {
    if (f.residual_std_nT <= kCompleteWithinFloor * f.floor_nT) {
      std::snprintf(buf, sizeof(buf),
                    "complete: the held-out residual (%.3f nT) is within %.1fx its noise floor "
                    "(%.3f nT, its spectrum's white level above %.1f Hz)",
                    f.residual_std_nT, kCompleteWithinFloor, f.floor_nT, f.band_lo_hz);
      return buf;
    }
    // Above the floor by less than a term must gain: structure, but none the search resolves.
    if (f.residual_std_nT <= f.floor_nT + resolution_nT) {
      std::snprintf(buf, sizeof(buf),
                    "below the resolution: the held-out residual (%.3f nT) is above %.1fx its "
                    "noise floor (%.3f nT, its spectrum's white level above %.1f Hz), by less "
                    "than the %.3f nT a term must gain; what remains is too small for the search "
                    "to resolve, not noise",
                    f.residual_std_nT, kCompleteWithinFloor, f.floor_nT, f.band_lo_hz,
                    resolution_nT);
      return buf;
    }
    return "structure remains: " + remainder_description(dx);
  }
  if (x.computed && !x.within_noise) {
    std::string chans;
    for (size_t k = 0; k < x.channels.size() && k < 3; ++k) {
      if (x.channels[k].second <= 0) break;
      chans += (k ? ", " : "") + x.channels[k].first;
    }
    std::snprintf(buf, sizeof(buf),
                  "structure remains: %.1f%% ± %.1f%% of the held-out residual is predictable "
                  "(noise floor %.1f%%), mostly from %s, and no term of the search explains it",
                  100 * x.share, 100 * x.uncertainty, 100 * x.noise_floor,
                  chans.empty() ? "no single channel" : chans.c_str());
    return buf;
  }
  if (x.computed) {
    std::snprintf(buf, sizeof(buf),
                  "complete: what remains is within noise (predictable share %.1f%% ± %.1f%%, "
                  "noise floor %.1f%%; predictable part %.3f nT rms, resolution %.3f nT; the "
                  "held-out lines are too short for a spectral floor)",
                  100 * x.share, 100 * x.uncertainty, 100 * x.noise_floor,
                  std::sqrt(x.share) * dx.baseline_std_nT, resolution_nT);
    return buf;
  }
  return "no candidate explains 5 % on both halves (the explainable share was not computed)";
}

}  // namespace

// Any verdict but "add" ends with the candidate one half of the held-out lines cannot confirm
// (one_half_term.h); "" when there is none.
std::string verdict_of(const Diagnosis& dx, double resolution_nT) {
  return verdict_before_one_half(dx, resolution_nT) + one_half_clause(dx.one_half);
}

}  // namespace magcomp::diagnose_search
