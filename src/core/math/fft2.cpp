// magcomp: the 2-D FFT of a grid (see fft2.h).
#include "magcomp/core/math/fft2.h"

#include <complex>
#include <unsupported/Eigen/FFT>
#include <vector>

namespace magcomp {

void fft2(Eigen::MatrixXcd* m, bool inverse) {
  Eigen::FFT<double> fft;
  std::vector<std::complex<double>> in, out;
  for (int pass = 0; pass < 2; ++pass) {
    const Eigen::Index lines = pass == 0 ? m->rows() : m->cols();
    const Eigen::Index len = pass == 0 ? m->cols() : m->rows();
    in.resize(static_cast<size_t>(len));
    for (Eigen::Index l = 0; l < lines; ++l) {
      for (Eigen::Index k = 0; k < len; ++k)
        in[static_cast<size_t>(k)] = pass == 0 ? (*m)(l, k) : (*m)(k, l);
      if (inverse) {
        fft.inv(out, in);  // Eigen scales the inverse by 1/len
      } else {
        fft.fwd(out, in);
      }
      for (Eigen::Index k = 0; k < len; ++k)
        (pass == 0 ? (*m)(l, k) : (*m)(k, l)) = out[static_cast<size_t>(k)];
    }
  }
}

}  // namespace magcomp
