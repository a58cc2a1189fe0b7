// magcomp: terms of the term language: columns, names, words.
#include "magcomp/core/model/terms_expr.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "magcomp/core/error.h"

namespace magcomp {
namespace {

const char* kAxisLetters = "xyz";
const int kPairs[6][2] = {{0, 0}, {0, 1}, {0, 2}, {1, 1}, {1, 2}, {2, 2}};

const char* projection_name(Projection p) {
  switch (p) {
    case Projection::Field:
      return "field";
    case Projection::Induced:
      return "induced";
    case Projection::Scalar:
      return "scalar";
  }
  return "";
}

bool is_current(const std::string& name) { return name.rfind("cur_", 0) == 0; }

}  // namespace

ExprTerm::ExprTerm(Projection projection, SignalExpr signal, std::string alias)
    : projection_(projection), signal_(std::move(signal)), alias_(std::move(alias)) {
  if (projection_ == Projection::Induced && signal_.width() != 1) {
    throw Error("term '" + spec() + "': induced: needs a scalar signal (not B)");
  }
}

std::string ExprTerm::spec() const {
  return alias_.empty() ? std::string(projection_name(projection_)) + ":" + signal_.str() : alias_;
}

std::string ExprTerm::shape() const {
  SignalExpr s = signal_;
  for (auto& t : s.transforms) {
    // A ramp's knot places a piece of a learned law: terms at other knots are other pieces.
    if (t.has_param() && t.kind != TransformKind::Ramp) t.free = true;
  }
  return std::string(projection_name(projection_)) + ":" + s.str();
}

std::string ExprTerm::effect() const {
  if (alias_.rfind("current:", 0) == 0) {
    return "field of a wire carrying " + signal_.sources[0] +
           " (∝ I), projected on the field direction";
  }
  if (alias_.rfind("dcurrent:", 0) == 0) {
    return "inductive pick-up ∝ dI/dt of " + signal_.sources[0] +
           ", projected on the field direction";
  }
  if (alias_.rfind("rate:", 0) == 0) {
    return "field ∝ attitude rate " + signal_.sources[0] +
           " (vibration, control surfaces), projected";
  }
  const std::string s = signal_.str();
  switch (projection_) {
    case Projection::Field:
      return signal_.width() == 3
                 ? "body-fixed field linear in " + s + " (3x3), projected on the field direction"
                 : "body-fixed field ∝ " + s + ", projected on the field direction";
    case Projection::Induced:
      return "magnetisation induced by the Earth field, scaled by " + s;
    case Projection::Scalar:
      return "added to the scalar reading: " + s;
  }
  return "";
}

std::vector<std::string> ExprTerm::column_names() const {
  const std::string s = spec();
  std::vector<std::string> names;
  const int w = signal_.width();
  switch (projection_) {
    case Projection::Field:
      for (int i = 0; i < 3; ++i) {
        if (w == 1) {
          names.push_back(s + "." + kAxisLetters[i]);
        } else {
          for (int j = 0; j < 3; ++j) names.push_back(s + "." + kAxisLetters[i] + kAxisLetters[j]);
        }
      }
      break;
    case Projection::Induced:
      for (const auto& p : kPairs)
        names.push_back(s + "." + kAxisLetters[p[0]] + kAxisLetters[p[1]]);
      break;
    case Projection::Scalar:
      if (w == 1) {
        names.push_back(s);
      } else {
        for (int j = 0; j < 3; ++j) names.push_back(s + "." + kAxisLetters[j]);
      }
      break;
  }
  return names;
}

std::vector<std::string> ExprTerm::required_fields() const {
  std::vector<std::string> out;
  for (const auto& s : signal_.sources) {
    if (s == "B" || s == "Bt") continue;
    if (std::find(out.begin(), out.end(), s) == out.end()) out.push_back(s);
  }
  return out;
}

std::string ExprTerm::stream_column(int c) const {
  return "~" + signal_.str() + "~" + std::to_string(c);
}

Eigen::MatrixXd ExprTerm::signal_values(const TermInputs& in) const {
  const FlightData& d = *in.data;
  const Eigen::Index n = d.size();
  const int w = signal_.width();
  if (!signal_.transforms.empty() && d.has(stream_column(0))) {
    Eigen::MatrixXd x(n, w);
    for (int c = 0; c < w; ++c) x.col(c) = d.column(stream_column(c));
    return x;
  }
  if (signal_.has_free()) {
    throw Error("term '" + spec() +
                "': a free parameter (?) has no value yet: fit the model first");
  }
  Eigen::MatrixXd x = Eigen::MatrixXd::Ones(n, w);
  for (const auto& s : signal_.sources) {
    if (s == "B") {
      x.array() *= in.field_nT.array();
    } else if (s == "Bt") {
      x.array().colwise() *= in.total_nT.array();
    } else {
      x.array().colwise() *= d.column(s).array();
    }
  }
  return apply_transforms(signal_.transforms, d.tt(), x);
}

void ExprTerm::project(const TermInputs& in, const Eigen::MatrixXd& s,
                       Eigen::Ref<Eigen::MatrixXd> out) const {
  const int w = signal_.width();
  switch (projection_) {
    case Projection::Field:
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < w; ++j) {
          out.col(i * w + j) = in.direction.col(i).cwiseProduct(s.col(j));
        }
      }
      break;
    case Projection::Induced:
      for (int k = 0; k < 6; ++k) {
        out.col(k) =
            (in.direction.col(kPairs[k][0]).array() * in.direction.col(kPairs[k][1]).array() *
             in.total_nT.array() * s.col(0).array() / in.bt_scale_nT)
                .matrix();
      }
      break;
    case Projection::Scalar:
      out = s;
      break;
  }
}

void ExprTerm::build(const TermInputs& in, Eigen::Ref<Eigen::MatrixXd> out) const {
  project(in, signal_values(in), out);
}

std::string ExprTerm::with_parameters(const std::vector<double>& values) const {
  SignalExpr s = signal_;
  size_t k = 0;
  for (auto& t : s.transforms) {
    if (!t.free) continue;
    if (k >= values.size()) throw Error("term '" + spec() + "': too few parameter values");
    t.param = values[k++];
    t.free = false;
  }
  return std::string(projection_name(projection_)) + ":" + s.str();
}

std::vector<std::pair<std::string, double>> ExprTerm::parameters() const {
  std::vector<std::pair<std::string, double>> out;
  for (const auto& t : signal_.transforms) {
    if (!t.has_param() || t.free) continue;
    const std::string unit = t.kind == TransformKind::Power      ? "exponent"
                             : t.kind == TransformKind::Delay    ? "delay_s"
                             : t.kind == TransformKind::Play     ? "half_width"
                             : t.kind == TransformKind::Saturate ? "level"
                             : t.kind == TransformKind::Step     ? "threshold"
                             : t.kind == TransformKind::Ramp     ? "knot"
                                                                 : "time_constant_s";
    std::string name = t.str();
    name = name.substr(0, name.find('('));
    out.emplace_back(name + "." + unit, t.param);
  }
  return out;
}

std::string ExprTerm::size_in_words(const Eigen::VectorXd& c) const {
  char buf[128];
  if (projection_ == Projection::Scalar && signal_.sources.size() == 1 &&
      signal_.transforms.size() == 1 && signal_.transforms[0].kind == TransformKind::Derivative &&
      c.size() == 1) {
    std::snprintf(buf, sizeof(buf), "first-order response, time constant %.3g s", -c[0]);
    return buf;
  }
  const bool plain_current = signal_.sources.size() == 1 && is_current(signal_.sources[0]);
  const bool has_param = !parameters().empty();
  std::string unit = "nT per unit";
  if (plain_current && signal_.transforms.empty()) {
    unit = "nT/A";
  } else if (plain_current && signal_.transforms.size() == 1 &&
             signal_.transforms[0].kind == TransformKind::Derivative) {
    unit = "nT per A/s";
  }
  std::snprintf(buf, sizeof(buf), "%.3g %s", c.norm(), unit.c_str());
  std::string out = buf;
  if (has_param) {
    for (const auto& t : signal_.transforms) {
      if (!t.has_param() || t.free) continue;
      const char* what = t.kind == TransformKind::Power      ? "exponent %.3g"
                         : t.kind == TransformKind::Delay    ? "delay %.3g s"
                         : t.kind == TransformKind::Play     ? "play half-width %.3g"
                         : t.kind == TransformKind::Saturate ? "saturating at %.3g"
                         : t.kind == TransformKind::Step     ? "switching above %.3g"
                         : t.kind == TransformKind::Ramp     ? "hinge at %.3g"
                                                             : "time constant %.3g s";
      std::snprintf(buf, sizeof(buf), what, t.param);
      out += std::string(", ") + buf;
    }
  }
  return out;
}

std::unique_ptr<ExprTerm> parse_expr_term(const std::string& spec) {
  const auto colon = spec.find(':');
  if (colon == std::string::npos) return nullptr;
  const std::string kind = spec.substr(0, colon);
  const std::string rest = spec.substr(colon + 1);
  auto plain = [&](const char* what) {
    SignalExpr e = parse_signal(rest, spec);
    if (e.sources.size() != 1 || !e.transforms.empty() || e.sources[0] == "B") {
      throw Error("term '" + spec + "': " + what + " takes one channel name, e.g. " + what +
                  ":cur_strb (write field:... for an expression)");
    }
    return e;
  };
  if (kind == "current" || kind == "rate") {
    SignalExpr e = plain(kind.c_str());
    return std::make_unique<ExprTerm>(Projection::Field, e, kind + ":" + e.sources[0]);
  }
  if (kind == "dcurrent") {
    SignalExpr e = plain("dcurrent");
    const std::string alias = kind + ":" + e.sources[0];
    e.transforms.push_back({TransformKind::Derivative, 0.0, false});
    return std::make_unique<ExprTerm>(Projection::Field, e, alias);
  }
  if (kind == "field")
    return std::make_unique<ExprTerm>(Projection::Field, parse_signal(rest, spec));
  if (kind == "induced")
    return std::make_unique<ExprTerm>(Projection::Induced, parse_signal(rest, spec));
  if (kind == "scalar")
    return std::make_unique<ExprTerm>(Projection::Scalar, parse_signal(rest, spec));
  return nullptr;
}

}  // namespace magcomp
