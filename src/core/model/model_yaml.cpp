// magcomp: model YAML load and atomic save.
#include <yaml-cpp/yaml.h>

#include <unistd.h>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <set>

#include "magcomp/core/error.h"
#include "magcomp/core/io/file_io.h"
#include "magcomp/core/io/paths.h"
#include "magcomp/core/model/model.h"

namespace magcomp {
namespace {

template <typename T>
T get(const YAML::Node& node, const std::string& path, const std::string& key) {
  try {
    return node.as<T>();
  } catch (const YAML::Exception&) {
    throw Error(path + ": key '" + key + "' has the wrong type");
  }
}

void warn_unknown(const YAML::Node& node, const std::set<std::string>& known,
                  const std::string& path, const std::string& prefix) {
  std::set<std::string> seen;
  for (const auto& kv : node) {
    const std::string key = kv.first.as<std::string>();
    if (!seen.insert(key).second) throw Error(path + ": key '" + prefix + key + "' given twice");
    if (!known.count(key)) {
      std::cerr << "warning: " << path << ": unknown key '" << prefix << key << "' ignored\n";
    }
  }
}

std::string directory_of(const std::string& path) {
  const auto slash = path.find_last_of('/');
  return slash == std::string::npos ? std::string(".") : path.substr(0, slash);
}

Eigen::VectorXd to_vector(const std::vector<double>& v) {
  return Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size()));
}

std::vector<double> to_std(const Eigen::VectorXd& v) { return {v.data(), v.data() + v.size()}; }

// `neural.training`: the optimiser's settings.
NeuralTraining parse_neural_training(const YAML::Node& t, const std::string& path) {
  NeuralTraining r;
  if (!t.IsMap()) throw Error(path + ": key 'neural.training' must be a map");
  warn_unknown(t,
               {"epochs", "batch", "learning_rate", "lr_decay", "weight_decay", "channel_sparsity",
                "channel_cut", "patience", "seed", "stride", "threads", "fit_output_gain"},
               path, "neural.training.");
  if (t["epochs"]) r.epochs = get<int>(t["epochs"], path, "neural.training.epochs");
  if (t["batch"]) r.batch = get<int>(t["batch"], path, "neural.training.batch");
  if (t["learning_rate"])
    r.learning_rate = get<double>(t["learning_rate"], path, "neural.training.learning_rate");
  if (t["lr_decay"]) r.lr_decay = get<double>(t["lr_decay"], path, "neural.training.lr_decay");
  if (t["weight_decay"])
    r.weight_decay = get<double>(t["weight_decay"], path, "neural.training.weight_decay");
  if (t["channel_sparsity"])
    r.channel_sparsity =
        get<double>(t["channel_sparsity"], path, "neural.training.channel_sparsity");
  if (t["channel_cut"])
    r.channel_cut = get<double>(t["channel_cut"], path, "neural.training.channel_cut");
  if (t["patience"]) r.patience = get<int>(t["patience"], path, "neural.training.patience");
  if (t["seed"]) r.seed = get<std::uint64_t>(t["seed"], path, "neural.training.seed");
  if (t["stride"]) r.stride = get<int>(t["stride"], path, "neural.training.stride");
  if (t["threads"]) r.threads = get<int>(t["threads"], path, "neural.training.threads");
  if (t["fit_output_gain"])
    r.fit_output_gain = get<bool>(t["fit_output_gain"], path, "neural.training.fit_output_gain");
  return r;
}

// `neural.normalisation`: each feature's mean and std and the target's, one per feature.
void parse_neural_normalisation(const YAML::Node& z, const std::string& path, NeuralSpec* s) {
  warn_unknown(z,
               {"feature_mean", "feature_std", "target_mean_nT", "target_std_nT", "column_scale"},
               path, "neural.normalisation.");
  for (const char* k : {"feature_mean", "feature_std", "target_mean_nT", "target_std_nT"}) {
    if (!z[k]) throw Error(path + ": key 'neural.normalisation." + k + "' missing");
  }
  s->feature_mean = to_vector(
      get<std::vector<double>>(z["feature_mean"], path, "neural.normalisation.feature_mean"));
  s->feature_std = to_vector(
      get<std::vector<double>>(z["feature_std"], path, "neural.normalisation.feature_std"));
  s->target_mean = get<double>(z["target_mean_nT"], path, "neural.normalisation.target_mean_nT");
  s->target_std = get<double>(z["target_std_nT"], path, "neural.normalisation.target_std_nT");
  if (s->feature_mean.size() != static_cast<Eigen::Index>(s->features.size()) ||
      s->feature_std.size() != static_cast<Eigen::Index>(s->features.size())) {
    throw Error(path + ": key 'neural.normalisation' has " +
                std::to_string(s->feature_mean.size()) + " means for " +
                std::to_string(s->features.size()) + " features");
  }
  if (!(s->target_std > 0) || !(s->feature_std.array() > 0).all()) {
    throw Error(path + ": key 'neural.normalisation' holds a non-positive std");
  }
  if (z["column_scale"]) {
    s->column_scale = to_vector(
        get<std::vector<double>>(z["column_scale"], path, "neural.normalisation.column_scale"));
    if (!(s->column_scale.array() > 0).all())
      throw Error(path + ": key 'neural.normalisation.column_scale' holds a non-positive scale");
  }
}

NeuralSpec parse_neural(const YAML::Node& n, const std::string& path, size_t tl_columns) {
  if (!n.IsMap()) throw Error(path + ": key 'neural' must be a map");
  warn_unknown(n,
               {"architecture", "mode", "features", "window", "hidden", "reference", "training",
                "normalisation", "tl_delta", "weights", "version", "train_flights",
                "validation_flights", "epochs_run", "validation_rmse_nT", "output_gain"},
               path, "neural.");
  NeuralSpec s;
  if (n["architecture"]) {
    s.architecture =
        parse_architecture(get<std::string>(n["architecture"], path, "neural.architecture"),
                           path + ": key 'neural.architecture'");
  }
  if (n["mode"]) {
    s.mode =
        parse_mode(get<std::string>(n["mode"], path, "neural.mode"), path + ": key 'neural.mode'");
  }
  if (n["features"])
    s.features = get<std::vector<std::string>>(n["features"], path, "neural.features");
  if (n["window"]) s.window = get<int>(n["window"], path, "neural.window");
  if (n["hidden"]) s.hidden = get<std::vector<int>>(n["hidden"], path, "neural.hidden");
  if (n["reference"]) s.reference = get<std::string>(n["reference"], path, "neural.reference");
  if (const YAML::Node t = n["training"]) s.training = parse_neural_training(t, path);
  if (const YAML::Node z = n["normalisation"]) parse_neural_normalisation(z, path, &s);
  if (n["tl_delta"]) {
    s.tl_delta = to_vector(get<std::vector<double>>(n["tl_delta"], path, "neural.tl_delta"));
    if (static_cast<size_t>(s.tl_delta.size()) != tl_columns) {
      throw Error(path + ": key 'neural.tl_delta' has " + std::to_string(s.tl_delta.size()) +
                  " values, the terms have " + std::to_string(tl_columns) + " columns");
    }
  }
  if (s.mode == NeuralMode::kCoefficients && s.feature_mean.size() > 0 &&
      static_cast<size_t>(s.column_scale.size()) != tl_columns) {
    throw Error(path + ": key 'neural.normalisation.column_scale' has " +
                std::to_string(s.column_scale.size()) + " values, the terms have " +
                std::to_string(tl_columns) + " columns");
  }
  if (n["weights"]) {
    s.weights = get<std::string>(n["weights"], path, "neural.weights");
    s.weights_path =
        s.weights.rfind('/', 0) == 0 ? s.weights : directory_of(path) + "/" + s.weights;
    if (s.feature_mean.size() == 0) {
      throw Error(path + ": key 'neural.normalisation' missing for trained weights");
    }
  }
  if (n["version"]) s.version = get<int>(n["version"], path, "neural.version");
  if (s.version != 1) {
    throw Error(path + ": key 'neural.version' is " + std::to_string(s.version) +
                ", this magcomp reads version 1");
  }
  if (n["train_flights"])
    s.train_flights =
        get<std::vector<std::string>>(n["train_flights"], path, "neural.train_flights");
  if (n["validation_flights"])
    s.validation_flights =
        get<std::vector<std::string>>(n["validation_flights"], path, "neural.validation_flights");
  if (n["epochs_run"]) s.epochs_run = get<int>(n["epochs_run"], path, "neural.epochs_run");
  if (n["validation_rmse_nT"])
    s.validation_rmse_nT = get<double>(n["validation_rmse_nT"], path, "neural.validation_rmse_nT");
  if (n["output_gain"]) s.output_gain = get<double>(n["output_gain"], path, "neural.output_gain");
  validate_neural_spec(s, path);
  return s;
}

void emit_neural(YAML::Emitter& out, const NeuralSpec& s) {
  out << YAML::Key << "neural" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "version" << YAML::Value << s.version;
  out << YAML::Key << "architecture" << YAML::Value << architecture_name(s.architecture);
  out << YAML::Key << "mode" << YAML::Value << mode_name(s.mode);
  out << YAML::Key << "features" << YAML::Value << YAML::Flow << s.features;
  out << YAML::Key << "window" << YAML::Value << s.window;
  out << YAML::Key << "hidden" << YAML::Value << YAML::Flow << s.hidden_or_default();
  out << YAML::Key << "reference" << YAML::Value << s.reference;
  const NeuralTraining& t = s.training;
  out << YAML::Key << "training" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "epochs" << YAML::Value << t.epochs;
  out << YAML::Key << "batch" << YAML::Value << t.batch;
  out << YAML::Key << "learning_rate" << YAML::Value << t.learning_rate;
  out << YAML::Key << "lr_decay" << YAML::Value << t.lr_decay;
  out << YAML::Key << "weight_decay" << YAML::Value << t.weight_decay;
  if (t.channel_sparsity > 0)
    out << YAML::Key << "channel_sparsity" << YAML::Value << t.channel_sparsity;
  if (t.channel_sparsity > 0 && t.channel_cut > 0)
    out << YAML::Key << "channel_cut" << YAML::Value << t.channel_cut;
  out << YAML::Key << "patience" << YAML::Value << t.patience;
  out << YAML::Key << "seed" << YAML::Value << t.seed;
  out << YAML::Key << "stride" << YAML::Value << t.stride;
  out << YAML::Key << "threads" << YAML::Value << t.threads;
  out << YAML::Key << "fit_output_gain" << YAML::Value << t.fit_output_gain;
  out << YAML::EndMap;
  if (s.feature_mean.size() > 0) {
    out << YAML::Key << "normalisation" << YAML::Value << YAML::BeginMap;
    out << YAML::Key << "feature_mean" << YAML::Value << YAML::Flow << to_std(s.feature_mean);
    out << YAML::Key << "feature_std" << YAML::Value << YAML::Flow << to_std(s.feature_std);
    out << YAML::Key << "target_mean_nT" << YAML::Value << s.target_mean;
    out << YAML::Key << "target_std_nT" << YAML::Value << s.target_std;
    if (s.column_scale.size() > 0)
      out << YAML::Key << "column_scale" << YAML::Value << YAML::Flow << to_std(s.column_scale);
    out << YAML::EndMap;
  }
  if (s.tl_delta.size() > 0) {
    out << YAML::Key << "tl_delta" << YAML::Value << YAML::Flow << to_std(s.tl_delta);
  }
  if (!s.weights.empty()) out << YAML::Key << "weights" << YAML::Value << s.weights;
  if (!s.train_flights.empty())
    out << YAML::Key << "train_flights" << YAML::Value << YAML::Flow << s.train_flights;
  if (!s.validation_flights.empty())
    out << YAML::Key << "validation_flights" << YAML::Value << YAML::Flow << s.validation_flights;
  if (s.epochs_run > 0) {
    out << YAML::Key << "epochs_run" << YAML::Value << s.epochs_run;
    out << YAML::Key << "validation_rmse_nT" << YAML::Value << s.validation_rmse_nT;
  }
  if (!s.weights.empty()) out << YAML::Key << "output_gain" << YAML::Value << s.output_gain;
  out << YAML::EndMap;
}

}  // namespace

namespace {

// The `terms` list: each term parsed once, so a bad one is named with the file.
void parse_terms(const YAML::Node& node, const std::string& path, Model* m) {
  if (!node.IsSequence()) throw Error(path + ": key 'terms' must be a list");
  m->terms.clear();
  std::string lag;  // a model has one lag (Model::add_term): a second would silently replace it
  for (const auto& t : node) {
    const std::string spec = get<std::string>(t, path, "terms");
    try {
      make_term(spec);
    } catch (const Error& e) {
      throw Error(path + ": key 'terms': " + e.what());
    }
    if (spec.rfind("lag:", 0) == 0) {
      if (!lag.empty())
        throw Error(path + ": key 'terms': two lags (" + lag + ", " + spec +
                    "): a model has one lag of its scalar");
      lag = spec;
    }
    m->add_term(spec);
  }
}

// A list of terms of the model (as `terms` writes them) under `key`: `black_box_terms` (those
// that form a learned law) or `slow_terms` (those fitted after the fit's first stage).
std::vector<std::string> parse_term_subset(const YAML::Node& node, const std::string& path,
                                           const std::string& key, const Model& m) {
  if (!node.IsSequence()) throw Error(path + ": key '" + key + "' must be a list");
  std::vector<std::string> out;
  for (const auto& t : node) {
    const std::string spec = get<std::string>(t, path, key);
    std::string canonical;
    try {
      canonical = make_term(spec)->spec();
    } catch (const Error& e) {
      throw Error(path + ": key '" + key + "': " + e.what());
    }
    if (std::find(m.terms.begin(), m.terms.end(), canonical) == m.terms.end())
      throw Error(path + ": key '" + key + "': '" + spec + "' is not among the model's terms");
    out.push_back(canonical);
  }
  return out;
}

// The `fit` map: method, calibration selection, band, order, trim, ridge lambda, reference.
FitSettings parse_fit_settings(const YAML::Node& f, const std::string& path) {
  FitSettings s;
  if (!f.IsMap()) throw Error(path + ": key 'fit' must be a map");
  warn_unknown(f,
               {"method", "lines", "windows", "band_hz", "order", "trim", "lambda", "reference",
                "slow_lines"},
               path, "fit.");
  if (f["method"]) {
    const std::string method = get<std::string>(f["method"], path, "fit.method");
    if (method == "bandpass") {
      s.method = FitMethod::kBandpass;
    } else if (method == "reference") {
      s.method = FitMethod::kReference;
    } else {
      throw Error(path + ": key 'fit.method' must be bandpass or reference, not '" + method + "'");
    }
  }
  if (f["lines"]) s.lines = get<std::vector<double>>(f["lines"], path, "fit.lines");
  for (double l : s.lines) {
    if (!std::isfinite(l)) throw Error(path + ": key 'fit.lines' holds a non-finite line number");
  }
  if (f["slow_lines"])
    s.slow_lines = get<std::vector<double>>(f["slow_lines"], path, "fit.slow_lines");
  for (double l : s.slow_lines) {
    if (!std::isfinite(l))
      throw Error(path + ": key 'fit.slow_lines' holds a non-finite line number");
  }
  if (f["windows"]) {
    for (const auto& w : f["windows"]) {
      auto pair = get<std::vector<double>>(w, path, "fit.windows");
      if (pair.size() != 2 || !(pair[1] >= pair[0]) || !std::isfinite(pair[0]) ||
          !std::isfinite(pair[1])) {
        throw Error(path + ": key 'fit.windows' entries must be [start_s, end_s]");
      }
      s.windows.push_back({pair[0], pair[1]});
    }
  }
  if (f["band_hz"]) {
    auto band = get<std::vector<double>>(f["band_hz"], path, "fit.band_hz");
    if (band.size() != 2 || !(band[0] > 0) || !(band[1] > band[0]) || !std::isfinite(band[1])) {
      throw Error(path + ": key 'fit.band_hz' must be [low, high] with 0 < low < high, finite");
    }
    s.band_low_hz = band[0];
    s.band_high_hz = band[1];
  }
  if (f["order"]) s.order = get<int>(f["order"], path, "fit.order");
  if (s.order < 1 || s.order > 10) throw Error(path + ": key 'fit.order' must be in 1..10");
  if (f["trim"]) s.trim = get<int>(f["trim"], path, "fit.trim");
  if (s.trim < 0) throw Error(path + ": key 'fit.trim' must be >= 0");
  if (f["lambda"]) s.lambda = get<double>(f["lambda"], path, "fit.lambda");
  if (!(s.lambda >= 0) || !(s.lambda <= 1e12))
    throw Error(path + ": key 'fit.lambda' must be in [0, 1e12]");
  if (f["reference"]) s.reference = get<std::string>(f["reference"], path, "fit.reference");
  if (s.method == FitMethod::kReference && s.reference.empty()) {
    throw Error(path + ": key 'fit.reference' is required when fit.method is reference");
  }
  return s;
}

// The `coefficients` map, one finite value per column of the model's terms.
void parse_coefficients(const YAML::Node& c, const std::string& path, Model* m) {
  if (!c.IsMap()) throw Error(path + ": key 'coefficients' must be a map column -> value");
  const std::vector<std::string> names = m->make_column_names();
  Eigen::VectorXd coef(static_cast<Eigen::Index>(names.size()));
  for (size_t i = 0; i < names.size(); ++i) {
    if (!c[names[i]]) {
      throw Error(path + ": key 'coefficients." + names[i] + "' missing for the model's terms");
    }
    coef[static_cast<Eigen::Index>(i)] = get<double>(c[names[i]], path, "coefficients." + names[i]);
    if (!std::isfinite(coef[static_cast<Eigen::Index>(i)])) {
      throw Error(path + ": key 'coefficients." + names[i] + "' is not finite");
    }
  }
  if (c.size() != names.size()) {
    throw Error(path + ": key 'coefficients' has " + std::to_string(c.size()) +
                " entries, the terms have " + std::to_string(names.size()) + " columns");
  }
  m->column_names = names;
  m->coefficients = coef;
}

// What the node needs of `fit_report`: the uncertainty of each sample.
void parse_fit_report(const YAML::Node& r, const std::string& path, Model* m) {
  if (r["noise_variance_nT2"]) {
    m->report.noise_variance_nT2 =
        get<double>(r["noise_variance_nT2"], path, "fit_report.noise_variance_nT2");
    if (!(m->report.noise_variance_nT2 >= 0) || !std::isfinite(m->report.noise_variance_nT2))
      throw Error(path + ": key 'fit_report.noise_variance_nT2' must be finite and >= 0");
  }
  if (r["holdout_error_variance_nT2"]) {
    m->report.holdout_error_variance_nT2 =
        get<double>(r["holdout_error_variance_nT2"], path, "fit_report.holdout_error_variance_nT2");
    if (!(m->report.holdout_error_variance_nT2 >= 0) ||
        !std::isfinite(m->report.holdout_error_variance_nT2))
      throw Error(path + ": key 'fit_report.holdout_error_variance_nT2' must be finite and >= 0");
  }
  if (r["residual_std_nT"])
    m->report.residual_std_nT =
        get<double>(r["residual_std_nT"], path, "fit_report.residual_std_nT");
  if (r["coefficient_covariance"]) {
    const auto flat = get<std::vector<double>>(r["coefficient_covariance"], path,
                                               "fit_report.coefficient_covariance");
    const auto p = static_cast<size_t>(m->coefficients.size());
    if (flat.size() != p * p) {
      throw Error(path + ": key 'fit_report.coefficient_covariance' has " +
                  std::to_string(flat.size()) + " values, the model needs " +
                  std::to_string(p * p));
    }
    m->report.coefficient_covariance.resize(static_cast<Eigen::Index>(p),
                                            static_cast<Eigen::Index>(p));
    for (size_t i = 0; i < p; ++i)
      for (size_t j = 0; j < p; ++j) {
        const double v = flat[i * p + j];
        if (!std::isfinite(v))
          throw Error(path + ": key 'fit_report.coefficient_covariance' holds a non-finite value");
        m->report.coefficient_covariance(static_cast<Eigen::Index>(i),
                                         static_cast<Eigen::Index>(j)) = v;
      }
  }
}

}  // namespace

static Model load_model_yaml_unchecked(const std::string& path_in) {
  const std::string path = is_directory(path_in) ? path_in + "/model.yaml" : path_in;
  YAML::Node root;
  require_regular_file(path, "model file");
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    throw Error(path + ": model file not found or not readable");
  } catch (const YAML::Exception& e) {
    throw Error(path + ": not valid YAML (line " + std::to_string(e.mark.line + 1) + ")");
  }
  if (!root.IsMap()) throw Error(path + ": model file must be a YAML map");
  warn_unknown(root,
               {"scalar", "vector", "terms", "black_box_terms", "slow_terms", "fit", "bt_scale_nT",
                "coefficients", "fit_report", "neural", "description"},
               path, "");
  Model m;
  if (!root["scalar"]) throw Error(path + ": key 'scalar' missing");
  if (!root["vector"]) throw Error(path + ": key 'vector' missing");
  m.scalar = get<std::string>(root["scalar"], path, "scalar");
  m.vector = get<std::string>(root["vector"], path, "vector");
  if (root["terms"]) parse_terms(root["terms"], path, &m);
  if (const YAML::Node b = root["black_box_terms"])
    m.black_box_terms = parse_term_subset(b, path, "black_box_terms", m);
  if (const YAML::Node b = root["slow_terms"]) {
    m.slow_terms = parse_term_subset(b, path, "slow_terms", m);
    for (const auto& t : m.slow_terms) {
      try {
        require_slow_term(t);
      } catch (const Error& e) {
        throw Error(path + ": key 'slow_terms': " + e.what());
      }
    }
  }
  if (root["bt_scale_nT"]) {
    m.bt_scale_nT = get<double>(root["bt_scale_nT"], path, "bt_scale_nT");
    if (!(m.bt_scale_nT > 0) || !std::isfinite(m.bt_scale_nT))
      throw Error(path + ": key 'bt_scale_nT' must be positive and finite");
  }
  if (const YAML::Node f = root["fit"]) m.fit = parse_fit_settings(f, path);
  if (!m.slow_terms.empty() && m.fit.method == FitMethod::kBandpass && m.fit.reference.empty()) {
    throw Error(path +
                ": key 'slow_terms' needs fit.reference (the field the slow terms are "
                "fitted against after the band-pass stage)");
  }
  if (const YAML::Node c = root["coefficients"]) parse_coefficients(c, path, &m);
  if (const YAML::Node r = root["fit_report"]; r && r.IsMap() && m.fitted()) {
    parse_fit_report(r, path, &m);
  }
  if (root["neural"]) m.neural = parse_neural(root["neural"], path, m.make_column_names().size());
  return m;
}

void save_model_yaml(const Model& m, const std::string& path,
                     const std::vector<std::string>& inputs) {
  YAML::Emitter out;
  out.SetDoublePrecision(17);
  out << YAML::BeginMap;
  out << YAML::Key << "scalar" << YAML::Value << m.scalar;
  out << YAML::Key << "vector" << YAML::Value << m.vector;
  out << YAML::Key << "terms" << YAML::Value << YAML::Flow << m.terms;
  if (!m.black_box_terms.empty())
    out << YAML::Key << "black_box_terms" << YAML::Value << YAML::Flow << m.black_box_terms;
  if (!m.slow_terms.empty())
    out << YAML::Key << "slow_terms" << YAML::Value << YAML::Flow << m.slow_terms;
  out << YAML::Key << "bt_scale_nT" << YAML::Value << m.bt_scale_nT;
  out << YAML::Key << "fit" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "method" << YAML::Value << fit_method_name(m.fit.method);
  if (!m.fit.lines.empty()) out << YAML::Key << "lines" << YAML::Value << YAML::Flow << m.fit.lines;
  if (!m.fit.windows.empty()) {
    out << YAML::Key << "windows" << YAML::Value << YAML::BeginSeq;
    for (const auto& w : m.fit.windows) {
      out << YAML::Flow << std::vector<double>{w.start_s, w.end_s};
    }
    out << YAML::EndSeq;
  }
  out << YAML::Key << "band_hz" << YAML::Value << YAML::Flow
      << std::vector<double>{m.fit.band_low_hz, m.fit.band_high_hz};
  out << YAML::Key << "order" << YAML::Value << m.fit.order;
  out << YAML::Key << "trim" << YAML::Value << m.fit.trim;
  out << YAML::Key << "lambda" << YAML::Value << m.fit.lambda;
  if (!m.fit.reference.empty()) out << YAML::Key << "reference" << YAML::Value << m.fit.reference;
  if (!m.fit.slow_lines.empty())
    out << YAML::Key << "slow_lines" << YAML::Value << YAML::Flow << m.fit.slow_lines;
  out << YAML::EndMap;
  if (m.fitted()) {
    out << YAML::Key << "coefficients" << YAML::Value << YAML::BeginMap;
    for (size_t i = 0; i < m.column_names.size(); ++i) {
      out << YAML::Key << m.column_names[i] << YAML::Value
          << m.coefficients[static_cast<Eigen::Index>(i)];
    }
    out << YAML::EndMap;
    out << YAML::Key << "fit_report" << YAML::Value << YAML::BeginMap;
    out << YAML::Key << "samples" << YAML::Value << static_cast<long long>(m.report.samples);
    out << YAML::Key << "segments" << YAML::Value << m.report.segments;
    out << YAML::Key << "condition_number" << YAML::Value << m.report.condition_number;
    out << YAML::Key << "residual_std_nT" << YAML::Value << m.report.residual_std_nT;
    out << YAML::Key << "warnings" << YAML::Value << YAML::Flow << m.report.warnings;
    if (!m.report.estimates.empty())
      out << YAML::Key << "estimates" << YAML::Value << YAML::Flow << m.report.estimates;
    if (std::isfinite(m.report.noise_variance_nT2)) {
      out << YAML::Key << "noise_variance_nT2" << YAML::Value << m.report.noise_variance_nT2;
    }
    if (std::isfinite(m.report.holdout_error_variance_nT2)) {
      out << YAML::Key << "holdout_error_variance_nT2" << YAML::Value
          << m.report.holdout_error_variance_nT2;
    }
    const Eigen::MatrixXd& cov = m.report.coefficient_covariance;
    if (cov.size() > 0) {  // row-major, P x P in column order
      std::vector<double> flat;
      for (Eigen::Index i = 0; i < cov.rows(); ++i)
        for (Eigen::Index j = 0; j < cov.cols(); ++j) flat.push_back(cov(i, j));
      out << YAML::Key << "coefficient_covariance" << YAML::Value << YAML::Flow << flat;
    }
    out << YAML::EndMap;
  }
  if (m.neural) emit_neural(out, *m.neural);
  out << YAML::EndMap;
  write_file_atomic(path, std::string("# magcomp model\n") + out.c_str() + "\n", inputs);
}

Model load_model_yaml(const std::string& path_in) {
  // A YAML oddity the checks above do not foresee (a key that is a list, say) is still one line
  // naming the file, never an escaping yaml-cpp exception.
  try {
    return load_model_yaml_unchecked(path_in);
  } catch (const Error&) {
    throw;
  } catch (const YAML::Exception& e) {
    throw Error(path_in + ": not a valid model file (" + e.msg + ", line " +
                std::to_string(e.mark.line + 1) + ")");
  } catch (const std::exception& e) {
    throw Error(path_in + ": cannot read the model file (" + e.what() + ")");
  }
}

}  // namespace magcomp
