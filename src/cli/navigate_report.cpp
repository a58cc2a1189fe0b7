// magcomp navigate: the report page (navigate_report.h).
#include "navigate_report.h"

#include "common.h"
#include "magcomp/core/io/file_io.h"
#include "magcomp/core/io/h5_array.h"
#include "magcomp/core/math/constants.h"
#include "magcomp/core/nav/ekf.h"
#include "magcomp/core/nav/nav_model.h"

namespace magcomp::cli {
namespace {

H5Array array_of(const Eigen::VectorXd& v) {
  H5Array a;
  a.dims = {static_cast<size_t>(v.size())};
  a.values.assign(v.data(), v.data() + v.size());
  return a;
}

}  // namespace

void write_navigation_report(const std::string& dir, const nav::FlightSamples& samples,
                             const Navigated& n, const Eigen::VectorXd& anomaly_nT,
                             const nav::AnomalyMap& map, const nlohmann::json& j,
                             const std::vector<std::string>& inputs) {
  make_report_dir(dir);
  const auto m = static_cast<Eigen::Index>(n.run.steps.size());
  Eigen::VectorXd t(m), tlat(m), tlon(m), ilat(m), ilon(m), flat(m), flon(m), en(m), ee(m), ien(m),
      iee(m), pnn(m), pee(m), pne(m), z(m), v(m), vv(m);
  const double t0 = m > 0 ? n.run.steps[0].t_s : 0.0;
  for (Eigen::Index i = 0; i < m; ++i) {
    const nav::NavigatorOutput& o = n.run.steps[static_cast<size_t>(i)];
    const nav::InsSample& tr =
        samples.truth[static_cast<size_t>(n.run.rows[static_cast<size_t>(i)])];
    const bool truth_ok = nav::invalid_ins_reason(tr).empty();
    t[i] = o.t_s - t0;
    tlat[i] = truth_ok ? tr.lat_rad * kRadToDeg : NAN;
    tlon[i] = truth_ok ? tr.lon_rad * kRadToDeg : NAN;
    ilat[i] = o.ins_lat_rad * kRadToDeg;
    ilon[i] = o.ins_lon_rad * kRadToDeg;
    flat[i] = o.lat_rad * kRadToDeg;
    flon[i] = o.lon_rad * kRadToDeg;
    en[i] = truth_ok ? nav::dlat_to_north_m(o.lat_rad - tr.lat_rad, tr.lat_rad) : NAN;
    ee[i] = truth_ok ? nav::dlon_to_east_m(o.lon_rad - tr.lon_rad, tr.lat_rad) : NAN;
    ien[i] = truth_ok ? nav::dlat_to_north_m(o.ins_lat_rad - tr.lat_rad, tr.lat_rad) : NAN;
    iee[i] = truth_ok ? nav::dlon_to_east_m(o.ins_lon_rad - tr.lon_rad, tr.lat_rad) : NAN;
    pnn[i] = o.position_cov_ned_m2(0, 0);
    pee[i] = o.position_cov_ned_m2(1, 1);
    pne[i] = o.position_cov_ned_m2(0, 1);
    z[i] = anomaly_nT[n.run.rows[static_cast<size_t>(i)]];
    v[i] = o.step.updated ? o.step.innovation_nT : NAN;
    vv[i] = o.step.innovation_var_nT2;
  }
  H5Array grid;
  grid.dims = {static_cast<size_t>(map.map_nT.rows()), static_cast<size_t>(map.map_nT.cols())};
  for (Eigen::Index r = 0; r < map.map_nT.rows(); ++r)
    for (Eigen::Index c = 0; c < map.map_nT.cols(); ++c)
      grid.values.push_back(map.mask.size() == 0 || map.mask(r, c) != 0 ? map.map_nT(r, c) : NAN);
  write_h5_arrays(dir + "/tracks.h5",
                  {{"t_s", array_of(t)},
                   {"true_lat_deg", array_of(tlat)},
                   {"true_lon_deg", array_of(tlon)},
                   {"ins_lat_deg", array_of(ilat)},
                   {"ins_lon_deg", array_of(ilon)},
                   {"filter_lat_deg", array_of(flat)},
                   {"filter_lon_deg", array_of(flon)},
                   {"error_north_m", array_of(en)},
                   {"error_east_m", array_of(ee)},
                   {"ins_error_north_m", array_of(ien)},
                   {"ins_error_east_m", array_of(iee)},
                   {"cov_north_m2", array_of(pnn)},
                   {"cov_east_m2", array_of(pee)},
                   {"cov_north_east_m2", array_of(pne)},
                   {"measurement_nT", array_of(z)},
                   {"innovation_nT", array_of(v)},
                   {"innovation_var_nT2", array_of(vv)},
                   {"map_lat_deg", array_of(map.lat_rad * kRadToDeg)},
                   {"map_lon_deg", array_of(map.lon_rad * kRadToDeg)},
                   {"map_nT", grid}},
                  inputs);
  write_file_atomic(dir + "/navigation.json", j.dump(2) + "\n", inputs);
  run_report_page("magcomp_nav_report.py", dir, "tracks.h5 and navigation.json");
}

}  // namespace magcomp::cli
