// magcomp: signal expressions: parsing, formatting and the causal transform stages.
#include "magcomp/core/model/signal.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <limits>

#include "magcomp/core/error.h"
#include "signal_pointwise.h"

namespace magcomp {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

struct TransformName {
  const char* name;
  TransformKind kind;
  bool param;
  const char* param_name;  // what the parameter is, for the list of known transforms
};
const TransformName kTransforms[] = {
    {"d", TransformKind::Derivative, false, ""},
    {"int", TransformKind::Integral, false, ""},
    {"abs", TransformKind::Abs, false, ""},
    {"lp", TransformKind::LowPass, true, "tau_s"},
    {"hp", TransformKind::HighPass, true, "tau_s"},
    {"delay", TransformKind::Delay, true, "s"},
    {"pow", TransformKind::Power, true, "p"},
    {"decay", TransformKind::Decay, true, "tau_s"},
    {"play", TransformKind::Play, true, "r"},
    {"sat", TransformKind::Saturate, true, "s"},
    {"step", TransformKind::Step, true, "x0"},
    {"ramp", TransformKind::Ramp, true, "x0"},
    // Long forms, read as the short ones.
    {"deriv", TransformKind::Derivative, false, ""},
    {"integral", TransformKind::Integral, false, ""},
    {"lowpass", TransformKind::LowPass, true, "tau_s"},
    {"highpass", TransformKind::HighPass, true, "tau_s"},
};

// "d, int, abs, lp(tau_s), ...": every transform by its short name, from the table above.
std::string known_transforms() {
  std::string list;
  for (size_t k = 0; k < sizeof kTransforms / sizeof kTransforms[0]; ++k) {
    const TransformName& t = kTransforms[k];
    bool short_form = true;
    for (size_t j = 0; j < k; ++j) short_form &= kTransforms[j].kind != t.kind;
    if (!short_form) continue;
    list += (list.empty() ? "" : ", ") + std::string(t.name) +
            (t.param ? "(" + std::string(t.param_name) + ")" : "");
  }
  return list;
}

const char* name_of(TransformKind k) {
  for (const auto& t : kTransforms)
    if (t.kind == k) return t.name;
  return "?";
}

bool valid_name(const std::string& s) {
  if (s.empty()) return false;
  for (char c : s) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.')) return false;
  }
  return true;
}

// Checks a parameter's range; returns "" when valid, else what is wrong.
std::string check_param(TransformKind k, double v) {
  if (!std::isfinite(v)) return "must be finite";
  switch (k) {
    case TransformKind::LowPass:
    case TransformKind::HighPass:
    case TransformKind::Decay:
      return v > 0 && v <= 1e6 ? "" : "time constant must be in (0, 1e6] s";
    case TransformKind::Delay:
      return v >= 0 && v <= 3600 ? "" : "delay must be in [0, 3600] s";
    case TransformKind::Power:
      return v != 0 && std::abs(v) <= 10 ? "" : "exponent must be non-zero and in [-10, 10]";
    case TransformKind::Play:
      return v >= 0 && v <= 1e9 ? "" : "half-width must be in [0, 1e9]";
    case TransformKind::Saturate:
      return v > 0 && v <= 1e9 ? "" : "saturation level must be in (0, 1e9]";
    case TransformKind::Step:
      return std::abs(v) <= 1e9 ? "" : "threshold must be in [-1e9, 1e9]";
    case TransformKind::Ramp:
      return std::abs(v) <= 1e9 ? "" : "knot must be in [-1e9, 1e9]";
    default:
      return "";
  }
}

// --- Stages -------------------------------------------------------------------------------

class DerivativeStage : public SignalStage {
 public:
  bool push(double t, double x, double* t_out, double* y) override {
    if (n_ == 0) {
      t1_ = t;
      x1_ = x;
      n_ = 1;
      return false;
    }
    *t_out = t1_;
    *y = n_ == 1 ? (x - x1_) / (t - t1_) : (x - x0_) / (t - t0_);
    t0_ = t1_;
    x0_ = x1_;
    t1_ = t;
    x1_ = x;
    n_ = 2;
    return true;
  }
  bool flush(double* t_out, double* y) override {
    if (n_ == 0) return false;
    *t_out = t1_;
    *y = n_ == 1 ? 0.0 : (x1_ - x0_) / (t1_ - t0_);
    return true;
  }
  void reset() override { n_ = 0; }

 private:
  int n_ = 0;
  double t0_ = 0, x0_ = 0, t1_ = 0, x1_ = 0;
};

class LowPassStage : public SignalStage {
 public:
  LowPassStage(double tau_s, bool high) : tau_(tau_s), high_(high) {}
  bool push(double t, double x, double* t_out, double* y) override {
    *t_out = t;
    if (!std::isfinite(x)) {  // NaN passes; the state waits for the next finite sample
      *y = kNaN;
      return true;
    }
    if (!init_) {
      s_ = x;
      init_ = true;
    } else {
      const double dt = t - tp_;
      if (dt != dt_) {  // a uniform flight computes its step's factor once
        dt_ = dt;
        a_ = std::exp(-dt / tau_);
      }
      s_ = a_ * s_ + (1 - a_) * x;
    }
    tp_ = t;
    *y = high_ ? x - s_ : s_;
    return true;
  }
  void reset() override { init_ = false; }

 private:
  double tau_;
  bool high_;
  bool init_ = false;
  double s_ = 0, tp_ = 0;
  double dt_ = kNaN, a_ = 1.0;  // the last step [s] and its factor exp(-dt / tau)
};

class IntegralStage : public SignalStage {
 public:
  bool push(double t, double x, double* t_out, double* y) override {
    *t_out = t;
    if (!std::isfinite(x)) {
      *y = kNaN;
      return true;
    }
    if (!init_) {
      acc_ = 0.0;
      init_ = true;
    } else {
      acc_ += 0.5 * (x + xp_) * (t - tp_);
    }
    xp_ = x;
    tp_ = t;
    *y = acc_;
    return true;
  }
  void reset() override { init_ = false; }

 private:
  bool init_ = false;
  double acc_ = 0, xp_ = 0, tp_ = 0;
};

class PlayStage : public SignalStage {
 public:
  explicit PlayStage(double half_width) : r_(half_width) {}
  bool push(double t, double x, double* t_out, double* y) override {
    *t_out = t;
    if (!std::isfinite(x)) {  // NaN passes; the state waits for the next finite sample
      *y = kNaN;
      return true;
    }
    s_ = init_ ? std::max(x - r_, std::min(x + r_, s_)) : x;
    init_ = true;
    *y = s_;
    return true;
  }
  void reset() override { init_ = false; }

 private:
  double r_;
  bool init_ = false;
  double s_ = 0;
};

class PointwiseStage : public SignalStage {
 public:
  PointwiseStage(TransformKind k, double p) : law_(k, p) {}
  bool push(double t, double x, double* t_out, double* y) override {
    *t_out = t;
    *y = law_(x);
    return true;
  }
  void reset() override {}

 private:
  PointwiseLaw law_;
};

class DelayStage : public SignalStage {
 public:
  explicit DelayStage(double delay_s) : delay_(delay_s) {}
  bool push(double t, double x, double* t_out, double* y) override {
    *t_out = t;
    if (delay_ == 0.0) {
      *y = x;
      return true;
    }
    hist_.push_back({t, x});
    const double q = t - delay_;
    while (hist_.size() >= 2 && hist_[1].first <= q) hist_.pop_front();
    if (q <= hist_.front().first) {  // before the first sample: hold it
      *y = hist_.front().second;
      return true;
    }
    const auto& a = hist_[0];
    const auto& b = hist_[1];  // a.t < q < b.t (q <= t = back.t)
    *y = a.second + (b.second - a.second) * ((q - a.first) / (b.first - a.first));
    return true;
  }
  void reset() override { hist_.clear(); }

 private:
  double delay_;
  std::deque<std::pair<double, double>> hist_;
};

}  // namespace

bool Transform::has_param() const {
  for (const auto& t : kTransforms)
    if (t.kind == kind) return t.param;
  return false;
}

std::string Transform::str() const {
  std::string s = name_of(kind);
  if (has_param()) s += "(" + (free ? std::string("?") : format_param(param)) + ")";
  return s;
}

std::string Transform::param_meaning() const {
  switch (kind) {
    case TransformKind::LowPass:
    case TransformKind::HighPass:
    case TransformKind::Decay:
      return "time constant (s)";
    case TransformKind::Delay:
      return "delay (s)";
    case TransformKind::Power:
      return "exponent";
    case TransformKind::Play:
      return "half-width (signal units)";
    case TransformKind::Saturate:
      return "saturation level (signal units)";
    case TransformKind::Step:
      return "threshold (signal units)";
    case TransformKind::Ramp:
      return "knot (signal units)";
    default:
      return "";
  }
}

std::string format_param(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.6g", v);
  return buf;
}

std::string SignalExpr::str() const {
  std::string s;
  for (size_t k = 0; k < sources.size(); ++k) s += (k ? "*" : "") + sources[k];
  for (const auto& t : transforms) s += "|" + t.str();
  return s;
}

bool SignalExpr::has_free() const {
  for (const auto& t : transforms)
    if (t.free) return true;
  return false;
}

int SignalExpr::lookahead() const {
  int n = 0;
  for (const auto& t : transforms) {
    if (t.kind == TransformKind::Derivative || t.kind == TransformKind::Decay) ++n;
  }
  return n;
}

int SignalExpr::width() const {
  for (const auto& s : sources)
    if (s == "B") return 3;
  return 1;
}

SignalExpr parse_signal(const std::string& text_in, const std::string& context) {
  std::string text;
  for (char c : text_in)
    if (!std::isspace(static_cast<unsigned char>(c))) text += c;
  auto fail = [&](const std::string& why) -> SignalExpr {
    throw Error("term '" + context + "': " + why);
  };
  if (text.empty()) return fail("empty signal (e.g. field:cur_heat|pow(2)|lp(?))");
  std::vector<std::string> parts;
  size_t start = 0;
  for (size_t i = 0; i <= text.size(); ++i) {
    if (i == text.size() || text[i] == '|') {
      parts.push_back(text.substr(start, i - start));
      start = i + 1;
    }
  }
  SignalExpr e;
  // The product of sources.
  start = 0;
  const std::string& product = parts[0];
  for (size_t i = 0; i <= product.size(); ++i) {
    if (i == product.size() || product[i] == '*') {
      const std::string name = product.substr(start, i - start);
      if (!valid_name(name)) {
        return fail("source '" + name +
                    "' is not a field name (letters, digits, '_' and '.'), B or Bt");
      }
      e.sources.push_back(name);
      start = i + 1;
    }
  }
  int vectors = 0;
  for (const auto& s : e.sources) vectors += s == "B";
  if (vectors > 1) return fail("at most one vector source (B) in a product");
  // The transforms.
  for (size_t k = 1; k < parts.size(); ++k) {
    const std::string& p = parts[k];
    const auto open = p.find('(');
    const std::string name = p.substr(0, open);
    const TransformName* tn = nullptr;
    for (const auto& t : kTransforms)
      if (name == t.name) tn = &t;
    if (!tn) {
      return fail("unknown transform '" + name + "' (known: " + known_transforms() + ")");
    }
    Transform tr;
    tr.kind = tn->kind;
    if (tn->param) {
      if (open == std::string::npos || p.back() != ')') {
        return fail("transform '" + name + "' needs a parameter: " + name + "(value) or " + name +
                    "(?)");
      }
      const std::string arg = p.substr(open + 1, p.size() - open - 2);
      if (arg == "?") {
        tr.free = true;
        tr.param = kNaN;
      } else {
        char* end = nullptr;
        tr.param = std::strtod(arg.c_str(), &end);
        if (arg.empty() || !end || *end != '\0') {
          return fail("transform '" + name + "': parameter '" + arg + "' is not a number or ?");
        }
        const std::string bad = check_param(tr.kind, tr.param);
        if (!bad.empty()) return fail("transform '" + p + "': " + bad);
      }
    } else if (open != std::string::npos) {
      return fail("transform '" + name + "' takes no parameter");
    }
    e.transforms.push_back(tr);
  }
  return e;
}

// --- Chains -------------------------------------------------------------------------------

TransformChain::TransformChain(const std::vector<Transform>& transforms) {
  for (const auto& t : transforms) {
    if (t.free) throw Error("signal: transform '" + t.str() + "' has no value yet");
    switch (t.kind) {
      case TransformKind::Derivative:
        stages_.push_back(std::make_unique<DerivativeStage>());
        break;
      case TransformKind::Integral:
        stages_.push_back(std::make_unique<IntegralStage>());
        break;
      case TransformKind::Abs:
      case TransformKind::Power:
      case TransformKind::Saturate:
      case TransformKind::Step:
      case TransformKind::Ramp:
        stages_.push_back(std::make_unique<PointwiseStage>(t.kind, t.param));
        break;
      case TransformKind::LowPass:
        stages_.push_back(std::make_unique<LowPassStage>(t.param, false));
        break;
      case TransformKind::HighPass:
        stages_.push_back(std::make_unique<LowPassStage>(t.param, true));
        break;
      case TransformKind::Delay:
        stages_.push_back(std::make_unique<DelayStage>(t.param));
        break;
      case TransformKind::Decay:
        stages_.push_back(std::make_unique<DerivativeStage>());
        stages_.push_back(std::make_unique<LowPassStage>(t.param, false));
        break;
      case TransformKind::Play:
        stages_.push_back(std::make_unique<PlayStage>(t.param));
        break;
    }
  }
}

void TransformChain::reset() {
  for (auto& s : stages_) s->reset();
}

}  // namespace magcomp
