// magcomp: a flight made of stream samples (see stream_sample.h).
#include "magcomp/core/model/stream_sample.h"

namespace magcomp {

FlightData samples_to_flight(const Model& model, const std::vector<std::string>& channels,
                             const std::vector<const StreamSample*>& samples,
                             const std::vector<int>* lines) {
  const Eigen::Index n = static_cast<Eigen::Index>(samples.size());
  Eigen::VectorXd tt(n), s(n), bx(n), by(n), bz(n), l(n);
  std::vector<Eigen::VectorXd> ch(channels.size(), Eigen::VectorXd(n));
  for (Eigen::Index k = 0; k < n; ++k) {
    const StreamSample& x = *samples[static_cast<size_t>(k)];
    tt[k] = x.t_s;
    s[k] = x.scalar_nT;
    bx[k] = x.vector_nT.x();
    by[k] = x.vector_nT.y();
    bz[k] = x.vector_nT.z();
    if (lines) l[k] = (*lines)[static_cast<size_t>(k)];
    for (size_t c = 0; c < channels.size(); ++c) ch[c][k] = x.channels[c];
  }
  FlightData w;
  w.set_source("stream");
  w.set("tt", tt);
  if (lines) w.set("line", l);
  w.set(model.scalar, s);
  w.set(model.vector + "_x", bx);
  w.set(model.vector + "_y", by);
  w.set(model.vector + "_z", bz);
  for (size_t c = 0; c < channels.size(); ++c) w.set(channels[c], ch[c]);
  return w;
}

}  // namespace magcomp
