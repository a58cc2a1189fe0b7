// magcomp: the rows a fit reads: the calibration runs of each flight (fit.lines, fit.windows), the
// slow stage's runs (fit.slow_lines), and their band-passed or plain stack (see fit/model_fit.h).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>
#include <thread>

#include "magcomp/core/error.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/math/butterworth.h"

namespace magcomp {

std::vector<std::pair<Eigen::Index, Eigen::Index>> calibration_runs(
    const FitSettings& s, const FlightData& data, const Eigen::MatrixXd& a,
    const Eigen::VectorXd& y, std::vector<std::string>* warnings) {
  std::vector<Eigen::Index> selected;
  if (s.lines.empty() && s.windows.empty()) {
    if (s.method == FitMethod::kBandpass)
      throw Error("fit: bandpass needs calibration segments (fit.lines or fit.windows)");
    selected.resize(static_cast<size_t>(data.size()));
    for (Eigen::Index i = 0; i < data.size(); ++i) selected[static_cast<size_t>(i)] = i;
  } else {
    selected = data.select(s.lines, s.windows);
  }
  return calibration_runs(s, data, std::move(selected), a, y, warnings);
}

std::vector<std::pair<Eigen::Index, Eigen::Index>> calibration_runs(
    const FitSettings& s, const FlightData& data, std::vector<Eigen::Index> selected,
    const Eigen::MatrixXd& a, const Eigen::VectorXd& y, std::vector<std::string>* warnings) {
  const bool bandpass = s.method == FitMethod::kBandpass;
  // Rows with NaN anywhere in the regression are dropped: a segment is split there.
  selected.erase(
      std::remove_if(selected.begin(), selected.end(),
                     [&](Eigen::Index i) { return !std::isfinite(y[i]) || !a.row(i).allFinite(); }),
      selected.end());
  const auto runs = data.contiguous_runs(selected, 1.5 * data.dt_s());
  const Eigen::Index min_len = bandpass ? 2 * s.trim + 10 : 1;
  std::vector<std::pair<Eigen::Index, Eigen::Index>> kept;
  for (const auto& run : runs) {
    const Eigen::Index len = run.second - run.first + 1;
    if (len >= min_len) {
      kept.push_back(run);
    } else if (warnings) {
      std::ostringstream w;
      w << data.source() << ": segment at tt " << data.tt()[run.first] << " s has " << len
        << " samples, too short for the band-pass and trim; skipped";
      warnings->push_back(w.str());
    }
  }
  return kept;
}

std::vector<std::pair<Eigen::Index, Eigen::Index>> slow_stage_runs(
    const FitSettings& s, const FlightData& data, const Eigen::MatrixXd& a,
    const Eigen::VectorXd& y, const std::vector<Eigen::Index>* rows) {
  auto runs = calibration_runs(s, data, a, y, nullptr);
  if (!rows && s.slow_lines.empty()) return runs;
  const std::vector<Eigen::Index> calibration = data.select(s.lines, s.windows);
  // The extra rows by line (a run never spans two lines), calibration rows left out.
  std::map<double, std::vector<Eigen::Index>> by_line;
  const Eigen::VectorXd line =
      data.has("line") ? Eigen::VectorXd(data.column("line")) : Eigen::VectorXd::Zero(data.size());
  const auto take = [&](Eigen::Index i) {
    if (i >= 0 && i < data.size() && std::isfinite(line[i]) &&
        !std::binary_search(calibration.begin(), calibration.end(), i))
      by_line[line[i]].push_back(i);
  };
  if (rows) {
    for (Eigen::Index i : *rows) take(i);
  } else {
    for (const double l : s.slow_lines)
      for (Eigen::Index i : data.select({l}, {})) take(i);
  }
  for (auto& [l, r] : by_line) {
    std::sort(r.begin(), r.end());
    r.erase(std::unique(r.begin(), r.end()), r.end());
    const auto more = calibration_runs(s, data, std::move(r), a, y, nullptr);
    runs.insert(runs.end(), more.begin(), more.end());
  }
  return runs;
}

Eigen::MatrixXd stack_runs(const FitSettings& s, double dt_s, const Eigen::MatrixXd& x,
                           const std::vector<std::pair<Eigen::Index, Eigen::Index>>& runs) {
  const bool bandpass = s.method == FitMethod::kBandpass;
  Eigen::Index rows = 0;
  for (const auto& [first, last] : runs) rows += (last - first + 1) - (bandpass ? 2 * s.trim : 0);
  Eigen::MatrixXd out(rows, x.cols());
  Eigen::Index r = 0;
  if (!(dt_s > 0) || !std::isfinite(dt_s)) {
    throw Error("fit: the flight's sample period (" + std::to_string(dt_s) + " s) is not positive");
  }
  const Butterworth bp = [&] {
    try {
      return Butterworth::band_pass(s.order, s.band_low_hz, s.band_high_hz, 1.0 / dt_s);
    } catch (const Error& e) {
      throw Error(std::string("fit.band_hz: ") + e.what());
    }
  }();
  for (const auto& [first, last] : runs) {
    const Eigen::Index len = last - first + 1;
    if (bandpass) {
      const Eigen::Index n = len - 2 * s.trim;
      static const int threads = std::max(1u, std::thread::hardware_concurrency());
      out.middleRows(r, n) =
          bp.filtfilt_parallel(x.middleRows(first, len), threads).middleRows(s.trim, n);
      r += n;
    } else {
      out.middleRows(r, len) = x.middleRows(first, len);
      r += len;
    }
  }
  return out;
}

std::vector<std::string> lines_flown_nowhere(const FitSettings& s,
                                             const std::vector<const FlightData*>& flights) {
  std::vector<std::string> warnings;
  std::string sources;
  for (const FlightData* f : flights) sources += (sources.empty() ? "" : ",") + f->source();
  for (const auto& [key, lines] :
       {std::make_pair("fit.lines", &s.lines), std::make_pair("fit.slow_lines", &s.slow_lines)}) {
    for (const double l : *lines) {
      if (std::any_of(flights.begin(), flights.end(), [&](const FlightData* f) {
            return f->has("line") && !f->select({l}, {}).empty();
          }))
        continue;
      char buf[96];
      std::snprintf(buf, sizeof(buf), "%s: line %.10g is flown on none of ", key, l);
      warnings.push_back(buf + sources + ": no row of it is fitted");
    }
  }
  return warnings;
}

}  // namespace magcomp
