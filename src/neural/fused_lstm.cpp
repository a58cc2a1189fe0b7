// magcomp: the LSTM with its backward pass written out (fused_lstm.h).
#include "magcomp/neural/fused_lstm.h"

#include <ATen/Parallel.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

namespace magcomp {
namespace {

template <typename S>
using RowMat = Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
// The rows of one step of a [B, T, width] tensor: row b at b * T * width.
template <typename S>
using StepMap = Eigen::Map<RowMat<S>, 0, Eigen::OuterStride<>>;
template <typename S>
using ConstStepMap = Eigen::Map<const RowMat<S>, 0, Eigen::OuterStride<>>;

constexpr int64_t kChunk = 128;  // batch rows per parallel chunk

// Runs fn(b0, b1, chunk) over fixed chunks of kChunk batch rows, in parallel on torch's intra-op
// threads; the chunks are the same whatever the thread count, so sums over them (reduced in
// chunk order by the caller) are reproducible.
template <typename Fn>
void for_chunks(int64_t B, const Fn& fn) {
  const int64_t chunks = (B + kChunk - 1) / kChunk;
  at::parallel_for(0, chunks, 1, [&](int64_t c0, int64_t c1) {
    for (int64_t c = c0; c < c1; ++c) fn(c * kChunk, std::min(B, (c + 1) * kChunk), c);
  });
}

// Step t of rows [b0, b1) of a [B, T, width] tensor's data.
template <typename S>
ConstStepMap<S> step(const S* data, int64_t b0, int64_t b1, int64_t t, int64_t T, int64_t width) {
  return ConstStepMap<S>(data + (b0 * T + t) * width, b1 - b0, width,
                         Eigen::OuterStride<>(T * width));
}
template <typename S>
StepMap<S> step(S* data, int64_t b0, int64_t b1, int64_t t, int64_t T, int64_t width) {
  return StepMap<S>(data + (b0 * T + t) * width, b1 - b0, width, Eigen::OuterStride<>(T * width));
}

// The rows [b0 * T, b1 * T) of a [B, T, width] tensor's data, as a matrix.
template <typename S>
Eigen::Map<const RowMat<S>> rows(const S* data, int64_t b0, int64_t b1, int64_t T, int64_t width) {
  return Eigen::Map<const RowMat<S>>(data + b0 * T * width, (b1 - b0) * T, width);
}
template <typename S>
Eigen::Map<RowMat<S>> rows(S* data, int64_t b0, int64_t b1, int64_t T, int64_t width) {
  return Eigen::Map<RowMat<S>>(data + b0 * T * width, (b1 - b0) * T, width);
}

// One layer forward over batch rows [b0, b1): in [B, T, n_in]; w_ih [4H, n_in], w_hh [4H, H],
// bias [4H] (both biases); writes act [B, T, 4H] (the gates i, f, g, o after their
// nonlinearity), cell [B, T, H], tcell [B, T, H] (tanh of the cell) and out [B, T, H].
template <typename S>
void forward_rows(int64_t b0, int64_t b1, int64_t T, int64_t n_in, int64_t H, const S* in,
                  const S* w_ih, const S* w_hh, const S* bias, S* act, S* cell, S* tcell, S* out) {
  const int64_t nb = b1 - b0, G = 4 * H;
  const Eigen::Map<const RowMat<S>> wih(w_ih, G, n_in), whh(w_hh, G, H);
  const Eigen::Map<const Eigen::Matrix<S, 1, Eigen::Dynamic>> b(bias, G);
  // The input projection of every step at once, into act (overwritten step by step below).
  auto pre = rows(act, b0, b1, T, G);
  pre.noalias() = rows(in, b0, b1, T, n_in) * wih.transpose();
  pre.rowwise() += b;
  const RowMat<S> whh_t = whh.transpose();
  RowMat<S> h = RowMat<S>::Zero(nb, H), c = RowMat<S>::Zero(nb, H), g(nb, G);
  for (int64_t t = 0; t < T; ++t) {
    StepMap<S> a = step(act, b0, b1, t, T, G);
    g = a;
    g.noalias() += h * whh_t;
    a.leftCols(2 * H) = g.leftCols(2 * H).array().logistic();
    a.middleCols(2 * H, H) = g.middleCols(2 * H, H).array().tanh();
    a.rightCols(H) = g.rightCols(H).array().logistic();
    c.array() = a.middleCols(H, H).array() * c.array() +
                a.leftCols(H).array() * a.middleCols(2 * H, H).array();
    StepMap<S> tc = step(tcell, b0, b1, t, T, H);
    tc = c.array().tanh();
    h.array() = a.rightCols(H).array() * tc.array();
    step(cell, b0, b1, t, T, H) = c;
    step(out, b0, b1, t, T, H) = h;
  }
}

// The same layer backward over rows [b0, b1): d_out [B, T, H] is the gradient reaching each
// step's output from above (the layer above, or the loss at the last step); writes d_pre
// [B, T, 4H] (the gates' gradient before their nonlinearity), d_in [B, T, n_in] when asked, and
// this chunk's share of the weights' gradients: dw_ih [4H, n_in], dw_hh [4H, H], db [4H].
template <typename S>
void backward_rows(int64_t b0, int64_t b1, int64_t T, int64_t n_in, int64_t H, const S* in,
                   const S* w_ih, const S* w_hh, const S* act, const S* cell, const S* tcell,
                   const S* out, const S* d_out, S* d_pre, S* d_in, RowMat<S>* dw_ih,
                   RowMat<S>* dw_hh, RowMat<S>* db) {
  const int64_t nb = b1 - b0, G = 4 * H;
  const Eigen::Map<const RowMat<S>> wih(w_ih, G, n_in), whh(w_hh, G, H);
  RowMat<S> dh = RowMat<S>::Zero(nb, H), dc = RowMat<S>::Zero(nb, H);
  for (int64_t t = T - 1; t >= 0; --t) {
    const ConstStepMap<S> a = step(act, b0, b1, t, T, G);
    const ConstStepMap<S> tc = step(tcell, b0, b1, t, T, H);
    StepMap<S> dp = step(d_pre, b0, b1, t, T, G);
    dh += step(d_out, b0, b1, t, T, H);
    const auto i = a.leftCols(H).array(), f = a.middleCols(H, H).array(),
               g = a.middleCols(2 * H, H).array(), o = a.rightCols(H).array();
    dc.array() += dh.array() * o * (S(1) - tc.array().square());
    dp.leftCols(H).array() = dc.array() * g * i * (S(1) - i);
    if (t > 0) {
      dp.middleCols(H, H).array() =
          dc.array() * step(cell, b0, b1, t - 1, T, H).array() * f * (S(1) - f);
    } else {
      dp.middleCols(H, H).setZero();
    }
    dp.middleCols(2 * H, H).array() = dc.array() * i * (S(1) - g.square());
    dp.rightCols(H).array() = dh.array() * tc.array() * o * (S(1) - o);
    dc.array() *= f;
    dh.noalias() = dp * whh;
  }
  const auto dp_all = rows(static_cast<const S*>(d_pre), b0, b1, T, G);
  dw_ih->noalias() = dp_all.transpose() * rows(in, b0, b1, T, n_in);
  // The recurrent weights see the previous step's output: every row of d_pre against the row of
  // `out` before it, in one product, less the pairs that straddle two windows (t = 0).
  const auto out_all = rows(out, b0, b1, T, H);
  const int64_t m = nb * T - 1;
  dw_hh->noalias() = dp_all.bottomRows(m).transpose() * out_all.topRows(m);
  for (int64_t r = 1; r < nb; ++r)
    dw_hh->noalias() -= dp_all.row(r * T).transpose() * out_all.row(r * T - 1);
  *db = dp_all.colwise().sum();
  if (d_in) rows(d_in, b0, b1, T, n_in).noalias() = dp_all * wih;
}

struct FusedLstm : torch::autograd::Function<FusedLstm> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& x,
                               torch::TensorList weights) {
    const int64_t B = x.size(0), T = x.size(1), layers = static_cast<int64_t>(weights.size()) / 4;
    torch::Tensor in = x.contiguous();
    for (int64_t l = 0; l < layers; ++l) {
      const torch::Tensor w_ih = weights[4 * l].contiguous(),
                          w_hh = weights[4 * l + 1].contiguous();
      const torch::Tensor bias = (weights[4 * l + 2] + weights[4 * l + 3]).contiguous();
      const int64_t H = w_hh.size(1), n_in = in.size(2);
      torch::Tensor act = torch::empty({B, T, 4 * H}, x.options());
      torch::Tensor cell = torch::empty({B, T, H}, x.options());
      torch::Tensor tcell = torch::empty({B, T, H}, x.options());
      torch::Tensor out = torch::empty({B, T, H}, x.options());
      AT_DISPATCH_FLOATING_TYPES(x.scalar_type(), "fused_lstm_forward", [&] {
        for_chunks(B, [&](int64_t b0, int64_t b1, int64_t) {
          forward_rows<scalar_t>(
              b0, b1, T, n_in, H, in.data_ptr<scalar_t>(), w_ih.data_ptr<scalar_t>(),
              w_hh.data_ptr<scalar_t>(), bias.data_ptr<scalar_t>(), act.data_ptr<scalar_t>(),
              cell.data_ptr<scalar_t>(), tcell.data_ptr<scalar_t>(), out.data_ptr<scalar_t>());
        });
      });
      const std::string n = std::to_string(l);
      ctx->saved_data["in" + n] = in;
      ctx->saved_data["act" + n] = act;
      ctx->saved_data["cell" + n] = cell;
      ctx->saved_data["tcell" + n] = tcell;
      ctx->saved_data["out" + n] = out;
      ctx->saved_data["w_ih" + n] = w_ih;
      ctx->saved_data["w_hh" + n] = w_hh;
      in = out;
    }
    ctx->saved_data["layers"] = layers;
    ctx->saved_data["x_grad"] = x.requires_grad();
    return in.select(1, T - 1).contiguous();
  }

  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grad_out) {
    const int64_t layers = ctx->saved_data["layers"].toInt();
    const bool x_grad = ctx->saved_data["x_grad"].toBool();
    torch::autograd::variable_list grads(static_cast<size_t>(1 + 4 * layers));
    const std::string top = std::to_string(layers - 1);
    const torch::Tensor top_out = ctx->saved_data["out" + top].toTensor();
    const int64_t B = top_out.size(0), T = top_out.size(1);
    torch::Tensor d_out = torch::zeros_like(top_out);
    d_out.select(1, T - 1).copy_(grad_out[0]);
    for (int64_t l = layers - 1; l >= 0; --l) {
      const std::string n = std::to_string(l);
      const torch::Tensor in = ctx->saved_data["in" + n].toTensor();
      const torch::Tensor act = ctx->saved_data["act" + n].toTensor();
      const torch::Tensor cell = ctx->saved_data["cell" + n].toTensor();
      const torch::Tensor tcell = ctx->saved_data["tcell" + n].toTensor();
      const torch::Tensor out = ctx->saved_data["out" + n].toTensor();
      const torch::Tensor w_ih = ctx->saved_data["w_ih" + n].toTensor();
      const torch::Tensor w_hh = ctx->saved_data["w_hh" + n].toTensor();
      const int64_t H = w_hh.size(1), n_in = in.size(2);
      d_out = d_out.contiguous();
      const bool want_in = l > 0 || x_grad;
      torch::Tensor d_pre = torch::empty({B, T, 4 * H}, out.options());
      torch::Tensor d_in = want_in ? torch::empty({B, T, n_in}, out.options()) : torch::Tensor();
      const size_t k = static_cast<size_t>(1 + 4 * l);
      AT_DISPATCH_FLOATING_TYPES(out.scalar_type(), "fused_lstm_backward", [&] {
        using S = scalar_t;
        const int64_t chunks = (B + kChunk - 1) / kChunk;
        std::vector<RowMat<S>> dw_ih(static_cast<size_t>(chunks)),
            dw_hh(static_cast<size_t>(chunks)), db(static_cast<size_t>(chunks));
        for_chunks(B, [&](int64_t b0, int64_t b1, int64_t c) {
          const size_t u = static_cast<size_t>(c);
          backward_rows<S>(b0, b1, T, n_in, H, in.data_ptr<S>(), w_ih.data_ptr<S>(),
                           w_hh.data_ptr<S>(), act.data_ptr<S>(), cell.data_ptr<S>(),
                           tcell.data_ptr<S>(), out.data_ptr<S>(), d_out.data_ptr<S>(),
                           d_pre.data_ptr<S>(), want_in ? d_in.data_ptr<S>() : nullptr, &dw_ih[u],
                           &dw_hh[u], &db[u]);
        });
        for (size_t u = 1; u < dw_ih.size(); ++u) {  // in chunk order: reproducible
          dw_ih[0] += dw_ih[u];
          dw_hh[0] += dw_hh[u];
          db[0] += db[u];
        }
        const auto tensor_of = [&](const RowMat<S>& m, std::vector<int64_t> shape) {
          return torch::from_blob(const_cast<S*>(m.data()), shape, out.options()).clone();
        };
        grads[k] = tensor_of(dw_ih[0], {4 * H, n_in});
        grads[k + 1] = tensor_of(dw_hh[0], {4 * H, H});
        grads[k + 2] = tensor_of(db[0], {4 * H});
        grads[k + 3] = grads[k + 2].clone();
      });
      if (want_in) d_out = d_in;
    }
    grads[0] = x_grad ? d_out : torch::Tensor();
    return grads;
  }
};

}  // namespace

torch::Tensor fused_lstm_last(const torch::Tensor& x, const std::vector<torch::Tensor>& weights) {
  TORCH_CHECK(x.dim() == 3 && !weights.empty() && weights.size() % 4 == 0,
              "fused_lstm_last: x [B, T, F] and four weights per layer");
  return FusedLstm::apply(x, torch::TensorList(weights));
}

}  // namespace magcomp
