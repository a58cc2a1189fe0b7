// magcomp: model YAML load and atomic save.
#include <yaml-cpp/yaml.h>

#include <unistd.h>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <set>

#include "magcomp/core/error.h"
#include "magcomp/core/model.h"

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

}  // namespace

Model load_model_yaml(const std::string& path) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    throw Error(path + ": model file not found or not readable");
  } catch (const YAML::Exception& e) {
    throw Error(path + ": not valid YAML (line " + std::to_string(e.mark.line + 1) + ")");
  }
  if (!root.IsMap()) throw Error(path + ": model file must be a YAML map");
  warn_unknown(root,
               {"scalar", "vector", "terms", "fit", "bt_scale_nT", "coefficients", "fit_report",
                "neural", "description"},
               path, "");
  Model m;
  if (!root["scalar"]) throw Error(path + ": key 'scalar' missing");
  if (!root["vector"]) throw Error(path + ": key 'vector' missing");
  m.scalar = get<std::string>(root["scalar"], path, "scalar");
  m.vector = get<std::string>(root["vector"], path, "vector");
  if (root["terms"]) {
    if (!root["terms"].IsSequence()) throw Error(path + ": key 'terms' must be a list");
    m.terms.clear();
    for (const auto& t : root["terms"]) {
      const std::string spec = get<std::string>(t, path, "terms");
      try {
        make_term(spec);
      } catch (const Error& e) {
        throw Error(path + ": key 'terms': " + e.what());
      }
      m.add_term(spec);
    }
  }
  if (root["bt_scale_nT"]) {
    m.bt_scale_nT = get<double>(root["bt_scale_nT"], path, "bt_scale_nT");
    if (!(m.bt_scale_nT > 0)) throw Error(path + ": key 'bt_scale_nT' must be positive");
  }
  if (const YAML::Node f = root["fit"]) {
    if (!f.IsMap()) throw Error(path + ": key 'fit' must be a map");
    warn_unknown(f,
                 {"method", "lines", "windows", "band_hz", "order", "trim", "lambda", "reference"},
                 path, "fit.");
    FitSettings& s = m.fit;
    if (f["method"]) s.method = get<std::string>(f["method"], path, "fit.method");
    if (s.method != "bandpass" && s.method != "reference") {
      throw Error(path + ": key 'fit.method' must be bandpass or reference, not '" + s.method +
                  "'");
    }
    if (f["lines"]) s.lines = get<std::vector<double>>(f["lines"], path, "fit.lines");
    if (f["windows"]) {
      for (const auto& w : f["windows"]) {
        auto pair = get<std::vector<double>>(w, path, "fit.windows");
        if (pair.size() != 2 || !(pair[1] >= pair[0])) {
          throw Error(path + ": key 'fit.windows' entries must be [start_s, end_s]");
        }
        s.windows.push_back({pair[0], pair[1]});
      }
    }
    if (f["band_hz"]) {
      auto band = get<std::vector<double>>(f["band_hz"], path, "fit.band_hz");
      if (band.size() != 2 || !(band[0] > 0) || !(band[1] > band[0])) {
        throw Error(path + ": key 'fit.band_hz' must be [low, high] with 0 < low < high");
      }
      s.band_low_hz = band[0];
      s.band_high_hz = band[1];
    }
    if (f["order"]) s.order = get<int>(f["order"], path, "fit.order");
    if (s.order < 1 || s.order > 10) throw Error(path + ": key 'fit.order' must be in 1..10");
    if (f["trim"]) s.trim = get<int>(f["trim"], path, "fit.trim");
    if (s.trim < 0) throw Error(path + ": key 'fit.trim' must be >= 0");
    if (f["lambda"]) s.lambda = get<double>(f["lambda"], path, "fit.lambda");
    if (!(s.lambda >= 0)) throw Error(path + ": key 'fit.lambda' must be >= 0");
    if (f["reference"]) s.reference = get<std::string>(f["reference"], path, "fit.reference");
    if (s.method == "reference" && s.reference.empty()) {
      throw Error(path + ": key 'fit.reference' is required when fit.method is reference");
    }
  }
  if (const YAML::Node c = root["coefficients"]) {
    if (!c.IsMap()) throw Error(path + ": key 'coefficients' must be a map column -> value");
    const std::vector<std::string> names = m.make_column_names();
    Eigen::VectorXd coef(static_cast<Eigen::Index>(names.size()));
    for (size_t i = 0; i < names.size(); ++i) {
      if (!c[names[i]]) {
        throw Error(path + ": key 'coefficients." + names[i] + "' missing for the model's terms");
      }
      coef[static_cast<Eigen::Index>(i)] =
          get<double>(c[names[i]], path, "coefficients." + names[i]);
    }
    if (c.size() != names.size()) {
      throw Error(path + ": key 'coefficients' has " + std::to_string(c.size()) +
                  " entries, the terms have " + std::to_string(names.size()) + " columns");
    }
    m.column_names = names;
    m.coefficients = coef;
  }
  return m;
}

void save_model_yaml(const Model& m, const std::string& path) {
  YAML::Emitter out;
  out.SetDoublePrecision(17);
  out << YAML::BeginMap;
  out << YAML::Key << "scalar" << YAML::Value << m.scalar;
  out << YAML::Key << "vector" << YAML::Value << m.vector;
  out << YAML::Key << "terms" << YAML::Value << YAML::Flow << m.terms;
  out << YAML::Key << "bt_scale_nT" << YAML::Value << m.bt_scale_nT;
  out << YAML::Key << "fit" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "method" << YAML::Value << m.fit.method;
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
    out << YAML::EndMap;
  }
  out << YAML::EndMap;
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  {
    std::ofstream f(tmp);
    if (!f) throw Error(path + ": cannot write model file");
    f << "# magcomp model\n" << out.c_str() << "\n";
    if (!f.good()) {
      std::remove(tmp.c_str());
      throw Error(path + ": write failed");
    }
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    throw Error(path + ": cannot rename temporary file into place");
  }
}

}  // namespace magcomp
