// magcomp: how much of a held-out residual a flexible model of all channels can predict.
//
// Each channel gets a nonlinear basis (hinges at its quantiles, two low-passed forms, its rate)
// times the field direction and as a plain scalar; the held-out units (lines, or contiguous
// pieces of a line) are dealt into four folds, and each fold is predicted by a ridge model fitted
// on the other three. The share it predicts is
// compared with the same procedure on channels shifted circularly in time (which keeps every
// series' own structure but breaks any link with the residual): that null gives the noise floor.
#pragma once

#include <Eigen/Core>
#include <functional>
#include <string>
#include <utility>
#include <vector>

namespace magcomp {

/// The verdict on what remains after the model.
struct ExplainableShare {
  bool computed = false;
  double share = 0.0;        ///< fraction of the held-out residual variance predicted, cross-fitted
  double uncertainty = 0.0;  ///< 1 sigma: the null's spread and a bootstrap over held-out units
  double noise_floor = 0.0;  ///< what the null (shifted channels) reaches: mean + 2 sigma
  bool within_noise = true;  ///< share <= noise_floor: nothing predictable remains
  /// Channels by the share each predicts alone (cross-fitted), strongest first.
  std::vector<std::pair<std::string, double>> channels;
  /// Fraction of the predicted part's variance by time scale: "slower than 100 s",
  /// "10-100 s", "faster than 10 s".
  std::vector<std::pair<std::string, double>> time_scales;
  /// Held-out lines by the fraction of the predicted part's variance they hold, largest first.
  std::vector<std::pair<double, double>> lines;
};

/// Inputs: the residual on the held-out samples (line means removed; NaN elsewhere), the unit of
/// each sample (0, 1, ... in time order; -1: not held out), its line, the time base (s), the
/// field direction B̂ (N x 3) and the candidate channels (name, values over the whole flight).
/// `channels_read` (optional) is called once every channel has been read, before the fits: the
/// caller may let the channels' memory go.
ExplainableShare explainable_share(
    const Eigen::VectorXd& residual, const std::vector<int>& unit, const Eigen::VectorXd& line,
    const Eigen::Ref<const Eigen::VectorXd>& t_s, const Eigen::MatrixX3d& direction,
    const std::vector<std::pair<std::string, Eigen::Map<const Eigen::VectorXd>>>& channels,
    const std::function<void()>& channels_read = {});

}  // namespace magcomp
