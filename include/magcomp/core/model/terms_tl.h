// magcomp: the classical Tolles-Lawson term families (MagNav.jl column conventions).
#pragma once

#include "magcomp/core/model/term.h"

namespace magcomp {

/// Permanent magnetisation: a body-fixed field projected on the Earth-field direction.
/// Columns B̂x, B̂y, B̂z (dimensionless; coefficients in nT).
class PermanentTerm : public Term {
 public:
  std::string spec() const override { return "permanent"; }
  std::string effect() const override {
    return "permanent magnetisation: body-fixed field projected on the Earth-field direction";
  }
  std::vector<std::string> column_names() const override;
  int row_reach() const override { return 0; }
  void build(const TermInputs& in, Eigen::Ref<Eigen::MatrixXd> out) const override;
};

/// Induced magnetisation: a susceptibility matrix times the Earth field, projected.
/// 6 columns B̂i·Bj/Bt_scale for ij in xx xy xz yy yz zz; 5 drops zz; 3 keeps xx yy zz.
class InducedTerm : public Term {
 public:
  explicit InducedTerm(int columns) : columns_(columns) {}
  std::string spec() const override;
  std::string effect() const override {
    return "induced magnetisation: susceptibility times the Earth field, projected";
  }
  std::vector<std::string> column_names() const override;
  int row_reach() const override { return 0; }
  void build(const TermInputs& in, Eigen::Ref<Eigen::MatrixXd> out) const override;

 private:
  int columns_;
};

/// Eddy currents: a matrix times the Earth field's rate of change, projected.
/// 9 columns B̂i·dBj/Bt_scale (row-major xx xy xz yx ...); 8 drops zz; 3 keeps xx yy zz.
/// dB is per sample, not per second (MagNav.jl convention).
class EddyTerm : public Term {
 public:
  explicit EddyTerm(int columns) : columns_(columns) {}
  std::string spec() const override;
  std::string effect() const override {
    return "eddy currents: proportional to the rate of change of the Earth field in the body";
  }
  std::vector<std::string> column_names() const override;
  int row_reach() const override { return 1; }
  void build(const TermInputs& in, Eigen::Ref<Eigen::MatrixXd> out) const override;

 private:
  int columns_;
};

/// Finite differences of the vector field: dBx, dBy, dBz in nT per sample.
class FdmTerm : public Term {
 public:
  std::string spec() const override { return "fdm"; }
  std::string effect() const override { return "rate of change of the vector field (nT/sample)"; }
  std::vector<std::string> column_names() const override;
  int row_reach() const override { return 1; }
  void build(const TermInputs& in, Eigen::Ref<Eigen::MatrixXd> out) const override;
};

/// A constant offset in nT (fitted only against a reference; invisible to a band-pass fit).
class BiasTerm : public Term {
 public:
  std::string spec() const override { return "bias"; }
  std::string effect() const override { return "constant offset of the scalar sensor"; }
  std::vector<std::string> column_names() const override { return {"bias"}; }
  bool bandpass_observable() const override { return false; }
  int row_reach() const override { return 0; }
  void build(const TermInputs& in, Eigen::Ref<Eigen::MatrixXd> out) const override;
};

}  // namespace magcomp
