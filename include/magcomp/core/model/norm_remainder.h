// magcomp: what Tolles-Lawson's first-order expansion of the scalar drops, computed from TL's own
// coefficients (the `norm` term).
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "magcomp/core/model/term.h"

namespace magcomp {

/// The aircraft's field at the scalar sensor as a vector, sensor frame, nT per sample (N x 3),
/// read from fitted TL coefficients: v = p + A B + E dB with p the `permanent` coefficients, A
/// the symmetric matrix of the `induced*` ones (an off-diagonal coefficient split evenly) and E
/// the `eddy*` ones, A and E divided by the model's Bt scale. Columns of other terms are ignored;
/// a family the model lacks contributes nothing.
Eigen::MatrixX3d tl_vector_field_nT(const TermInputs& in,
                                    const std::vector<std::string>& column_names,
                                    const Eigen::VectorXd& coefficients);

/// The exact norm's remainder, nT per sample: |B + v| - |B| - B̂·v, B the vector sensor's field
/// and v tl_vector_field_nT(). TL writes the scalar as |B| + B̂·v (its columns times its
/// coefficients give B̂·v exactly); the scalar sensor reads |B + v|. Second order in |v|/|B|:
/// (|v|² - (B̂·v)²) / (2|B|) to first approximation. NaN where the inputs are.
Eigen::VectorXd norm_remainder_nT(const TermInputs& in,
                                  const std::vector<std::string>& column_names,
                                  const Eigen::VectorXd& coefficients);

}  // namespace magcomp
