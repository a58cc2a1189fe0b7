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
template <typename S>
using Rows = Eigen::Map<RowMat<S>>;
template <typename S>
using ConstRows = Eigen::Map<const RowMat<S>>;

// Every tensor of a layer is time-major, [T, B, width]: the rows of one step are contiguous, so
// the recurrence reads and writes whole blocks, and the products over every step are products of
// whole [T * B, width] matrices.
constexpr int64_t kChunk = 128;      // batch rows per parallel chunk of the recurrence
constexpr int64_t kRowChunk = 4096;  // rows per parallel chunk of the products over every step

// Runs fn(r0, r1, chunk) over fixed chunks of `size` rows of n, in parallel on torch's intra-op
// threads; the chunks are the same whatever the thread count, so sums over them (reduced in
// chunk order by the caller) are reproducible.
template <typename Fn>
void for_chunks(int64_t n, int64_t size, const Fn& fn) {
  const int64_t chunks = (n + size - 1) / size;
  at::parallel_for(0, chunks, 1, [&](int64_t c0, int64_t c1) {
    for (int64_t c = c0; c < c1; ++c) fn(c * size, std::min(n, (c + 1) * size), c);
  });
}

// Rows [r0, r1) of a [rows, width] matrix's data.
template <typename S>
ConstRows<S> rows(const S* data, int64_t r0, int64_t r1, int64_t width) {
  return ConstRows<S>(data + r0 * width, r1 - r0, width);
}
template <typename S>
Rows<S> rows(S* data, int64_t r0, int64_t r1, int64_t width) {
  return Rows<S>(data + r0 * width, r1 - r0, width);
}

// The input projection of every step of a layer: pre [T * B, 4H] = in [T * B, n_in] w_ih^T + bias.
template <typename S>
void project(int64_t n, int64_t n_in, int64_t G, const S* in, const S* w_ih, const S* bias,
             S* pre) {
  const ConstRows<S> wih(w_ih, G, n_in);
  const Eigen::Map<const Eigen::Matrix<S, 1, Eigen::Dynamic>> b(bias, G);
  for_chunks(n, kRowChunk, [&](int64_t r0, int64_t r1, int64_t) {
    auto p = rows(pre, r0, r1, G);
    p.noalias() = rows(in, r0, r1, n_in) * wih.transpose();
    p.rowwise() += b;
  });
}

// One layer's recurrence over batch rows [b0, b1) of B: act [T, B, 4H] holds the input
// projection and is overwritten by the gates i, f, g, o after their nonlinearity; writes cell
// [T, B, H], tcell [T, B, H] (tanh of the cell) and out [T, B, H].
template <typename S>
void forward_rows(int64_t b0, int64_t b1, int64_t B, int64_t T, int64_t H, const S* w_hh, S* act,
                  S* cell, S* tcell, S* out) {
  const int64_t nb = b1 - b0, G = 4 * H;
  const RowMat<S> whh_t = ConstRows<S>(w_hh, G, H).transpose();
  RowMat<S> h = RowMat<S>::Zero(nb, H), c = RowMat<S>::Zero(nb, H), g(nb, G);
  for (int64_t t = 0; t < T; ++t) {
    const int64_t r0 = t * B + b0, r1 = t * B + b1;
    Rows<S> a = rows(act, r0, r1, G);
    g = a;
    g.noalias() += h * whh_t;
    a.leftCols(2 * H) = g.leftCols(2 * H).array().logistic();
    a.middleCols(2 * H, H) = g.middleCols(2 * H, H).array().tanh();
    a.rightCols(H) = g.rightCols(H).array().logistic();
    c.array() = a.middleCols(H, H).array() * c.array() +
                a.leftCols(H).array() * a.middleCols(2 * H, H).array();
    Rows<S> tc = rows(tcell, r0, r1, H);
    tc = c.array().tanh();
    h.array() = a.rightCols(H).array() * tc.array();
    rows(cell, r0, r1, H) = c;
    rows(out, r0, r1, H) = h;
  }
}

// The same recurrence backward over rows [b0, b1): d_out [T, B, H] is the gradient reaching each
// step's output from above (the layer above, or the loss at the last step); writes d_pre
// [T, B, 4H], the gates' gradient before their nonlinearity.
template <typename S>
void backward_rows(int64_t b0, int64_t b1, int64_t B, int64_t T, int64_t H, const S* w_hh,
                   const S* act, const S* cell, const S* tcell, const S* d_out, S* d_pre) {
  const int64_t nb = b1 - b0, G = 4 * H;
  const ConstRows<S> whh(w_hh, G, H);
  RowMat<S> dh = RowMat<S>::Zero(nb, H), dc = RowMat<S>::Zero(nb, H);
  for (int64_t t = T - 1; t >= 0; --t) {
    const int64_t r0 = t * B + b0, r1 = t * B + b1;
    const ConstRows<S> a = rows(act, r0, r1, G);
    const ConstRows<S> tc = rows(tcell, r0, r1, H);
    Rows<S> dp = rows(d_pre, r0, r1, G);
    dh += rows(d_out, r0, r1, H);
    const auto i = a.leftCols(H).array(), f = a.middleCols(H, H).array(),
               g = a.middleCols(2 * H, H).array(), o = a.rightCols(H).array();
    dc.array() += dh.array() * o * (S(1) - tc.array().square());
    dp.leftCols(H).array() = dc.array() * g * i * (S(1) - i);
    if (t > 0) {
      dp.middleCols(H, H).array() =
          dc.array() * rows(cell, r0 - B, r1 - B, H).array() * f * (S(1) - f);
    } else {
      dp.middleCols(H, H).setZero();
    }
    dp.middleCols(2 * H, H).array() = dc.array() * i * (S(1) - g.square());
    dp.rightCols(H).array() = dh.array() * tc.array() * o * (S(1) - o);
    dc.array() *= f;
    dh.noalias() = dp * whh;
  }
}

// The weights' gradients over rows [r0, r1) of every step (this chunk's share): dw_ih [4H, n_in],
// dw_hh [4H, H] (each row against the row of `out` one step before it; none at t = 0), db [4H];
// and d_in [T * B, n_in] there when asked.
template <typename S>
void weight_grads(int64_t r0, int64_t r1, int64_t B, int64_t n_in, int64_t H, const S* in,
                  const S* w_ih, const S* out, const S* d_pre, S* d_in, RowMat<S>* dw_ih,
                  RowMat<S>* dw_hh, RowMat<S>* db) {
  const int64_t G = 4 * H;
  const ConstRows<S> dp = rows(d_pre, r0, r1, G);
  dw_ih->noalias() = dp.transpose() * rows(in, r0, r1, n_in);
  const int64_t s0 = std::max(r0, B);  // the first row with a step before it
  if (s0 < r1) {
    dw_hh->noalias() = rows(d_pre, s0, r1, G).transpose() * rows(out, s0 - B, r1 - B, H);
  } else {
    dw_hh->setZero(G, H);
  }
  *db = dp.colwise().sum();
  if (d_in) rows(d_in, r0, r1, n_in).noalias() = dp * ConstRows<S>(w_ih, G, n_in);
}

struct FusedLstm : torch::autograd::Function<FusedLstm> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& x,
                               torch::TensorList weights) {
    const int64_t B = x.size(0), T = x.size(1), layers = static_cast<int64_t>(weights.size()) / 4;
    torch::Tensor in = x.transpose(0, 1).contiguous();  // [T, B, F]
    for (int64_t l = 0; l < layers; ++l) {
      const torch::Tensor w_ih = weights[4 * l].contiguous(),
                          w_hh = weights[4 * l + 1].contiguous();
      const torch::Tensor bias = (weights[4 * l + 2] + weights[4 * l + 3]).contiguous();
      const int64_t H = w_hh.size(1), n_in = in.size(2);
      torch::Tensor act = torch::empty({T, B, 4 * H}, x.options());
      torch::Tensor cell = torch::empty({T, B, H}, x.options());
      torch::Tensor tcell = torch::empty({T, B, H}, x.options());
      torch::Tensor out = torch::empty({T, B, H}, x.options());
      AT_DISPATCH_FLOATING_TYPES(x.scalar_type(), "fused_lstm_forward", [&] {
        using S = scalar_t;
        project<S>(T * B, n_in, 4 * H, in.data_ptr<S>(), w_ih.data_ptr<S>(), bias.data_ptr<S>(),
                   act.data_ptr<S>());
        for_chunks(B, kChunk, [&](int64_t b0, int64_t b1, int64_t) {
          forward_rows<S>(b0, b1, B, T, H, w_hh.data_ptr<S>(), act.data_ptr<S>(),
                          cell.data_ptr<S>(), tcell.data_ptr<S>(), out.data_ptr<S>());
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
    return in.select(0, T - 1).contiguous();
  }

  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grad_out) {
    const int64_t layers = ctx->saved_data["layers"].toInt();
    const bool x_grad = ctx->saved_data["x_grad"].toBool();
    torch::autograd::variable_list grads(static_cast<size_t>(1 + 4 * layers));
    const std::string top = std::to_string(layers - 1);
    const torch::Tensor top_out = ctx->saved_data["out" + top].toTensor();
    const int64_t T = top_out.size(0), B = top_out.size(1);
    torch::Tensor d_out = torch::zeros_like(top_out);
    d_out.select(0, T - 1).copy_(grad_out[0]);
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
      torch::Tensor d_pre = torch::empty({T, B, 4 * H}, out.options());
      torch::Tensor d_in = want_in ? torch::empty({T, B, n_in}, out.options()) : torch::Tensor();
      const size_t k = static_cast<size_t>(1 + 4 * l);
      AT_DISPATCH_FLOATING_TYPES(out.scalar_type(), "fused_lstm_backward", [&] {
        using S = scalar_t;
        for_chunks(B, kChunk, [&](int64_t b0, int64_t b1, int64_t) {
          backward_rows<S>(b0, b1, B, T, H, w_hh.data_ptr<S>(), act.data_ptr<S>(),
                           cell.data_ptr<S>(), tcell.data_ptr<S>(), d_out.data_ptr<S>(),
                           d_pre.data_ptr<S>());
        });
        const int64_t chunks = (T * B + kRowChunk - 1) / kRowChunk;
        std::vector<RowMat<S>> dw_ih(static_cast<size_t>(chunks)),
            dw_hh(static_cast<size_t>(chunks)), db(static_cast<size_t>(chunks));
        for_chunks(T * B, kRowChunk, [&](int64_t r0, int64_t r1, int64_t c) {
          const size_t u = static_cast<size_t>(c);
          weight_grads<S>(r0, r1, B, n_in, H, in.data_ptr<S>(), w_ih.data_ptr<S>(),
                          out.data_ptr<S>(), d_pre.data_ptr<S>(),
                          want_in ? d_in.data_ptr<S>() : nullptr, &dw_ih[u], &dw_hh[u], &db[u]);
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
    grads[0] = x_grad ? d_out.transpose(0, 1).contiguous() : torch::Tensor();
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
