// magcomp: the 2-D discrete Fourier transform of a grid, the one the simulator's maps and the
// navigation maps' upward continuation use.
#pragma once

#include <Eigen/Core>

namespace magcomp {

/// In-place 2-D FFT of `m` (rows, then columns; Eigen's FFT, no padding): forward, or inverse
/// scaled by 1/(rows * cols).
void fft2(Eigen::MatrixXcd* m, bool inverse);

}  // namespace magcomp
