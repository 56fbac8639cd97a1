#include "densemap/upsample/iln.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <memory>

#include "densemap/upsample/interpolation.hpp"
#include "iln_limits.hpp"

namespace densemap::upsample {
namespace {

using RowMatrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// As in tools/iln/iln.py.
constexpr float kPriorMinWeight = 1e-4F, kPriorMinRange = 1e-3F;

/// A per-thread object reused from call to call (fresh megabytes on every scan cost more in
/// page faults than the arithmetic). If the thread re-enters while it is in use (TBB lets a
/// waiting thread run another task), the nested call gets an object of its own. Lambdas must
/// capture get()'s reference: the thread_local itself names another thread's object there.
template <class T>
class Reused {
 public:
  Reused() {
    if (slot().busy) {
      own_ = std::make_unique<T>();
    } else {
      slot().busy = true;
    }
  }
  ~Reused() {
    if (!own_) slot().busy = false;
  }
  Reused(const Reused&) = delete;
  Reused& operator=(const Reused&) = delete;
  T& get() { return own_ ? *own_ : slot().value; }

 private:
  struct Slot {
    T value;
    bool busy = false;
  };
  static Slot& slot() {
    thread_local Slot s;
    return s;
  }
  std::unique_ptr<T> own_;
};

}  // namespace

std::size_t IlnModel::parameters() const { return parameters_; }

void IlnModel::convolve(const Conv& conv, const float* x, float* y, int rows, int cols,
                        bool relu_input) {
  const std::size_t plane = static_cast<std::size_t>(rows) * cols;
  const Eigen::Map<const RowMatrix> weight(conv.weight.data(), conv.out, conv.in * 9);
  tbb::parallel_for(tbb::blocked_range<int>(0, rows), [&](const tbb::blocked_range<int>& band) {
    const int n = (band.end() - band.begin()) * cols;
    thread_local RowMatrix patches;  // im2col of the band, zero padding 1; reused
    patches.resize(conv.in * 9, n);
    for (int ci = 0; ci < conv.in; ++ci) {
      const float* channel = x + ci * plane;
      for (int tap = 0; tap < 9; ++tap) {
        const int dy = tap / 3 - 1, dx = tap % 3 - 1;
        float* out = patches.row(ci * 9 + tap).data();
        for (int r = band.begin(); r != band.end(); ++r, out += cols) {
          const int sr = r + dy;
          if (sr < 0 || sr >= rows) {
            std::fill(out, out + cols, 0.0F);
            continue;
          }
          // out[c] = src[c + dx], zero where c + dx leaves the row.
          const float* src = channel + static_cast<std::size_t>(sr) * cols;
          const int lo = std::max(0, -dx), hi = std::min(cols, cols - dx);
          if (lo > 0) out[0] = 0.0F;
          if (hi < cols) out[cols - 1] = 0.0F;
          if (relu_input) {
            for (int c = lo; c < hi; ++c) out[c] = std::max(src[c + dx], 0.0F);
          } else {
            std::copy(src + lo + dx, src + hi + dx, out + lo);
          }
        }
      }
    }
    Eigen::Map<RowMatrix, 0, Eigen::OuterStride<>> result(
        y + static_cast<std::size_t>(band.begin()) * cols, conv.out, n,
        Eigen::OuterStride<>(static_cast<Eigen::Index>(plane)));
    result.noalias() = weight * patches;
    for (int co = 0; co < conv.out; ++co) result.row(co).array() += conv.bias[co];
  });
}

IlnEncoding IlnModel::encode(const RangeImage& input) const {
  IlnEncoding enc;
  encode(input, enc);
  return enc;
}

void IlnModel::encode(const RangeImage& input, IlnEncoding& enc) const {
  const int rows = input.layout.rows, cols = input.layout.cols;
  const std::size_t plane = static_cast<std::size_t>(rows) * cols;
  // The encoder's activations, kept per thread.
  Reused<std::array<std::vector<float>, 5>> buffers;
  auto& [x, head, features, inner, outer] = buffers.get();
  x.resize(plane);
  for (const auto buffer : {&head, &features, &inner, &outer}) buffer->resize(plane * width_);
  for (std::size_t i = 0; i < plane; ++i) x[i] = input.range[i] / max_range_;
  // f = h + body(h), h = head(x); each block adds conv2(relu(conv1(.))) to its input.
  convolve(head_, x.data(), head.data(), rows, cols, false);
  std::copy(head.begin(), head.end(), features.begin());
  for (std::size_t i = 0; i < body_.size(); i += 2) {
    convolve(body_[i], features.data(), inner.data(), rows, cols, false);
    convolve(body_[i + 1], inner.data(), outer.data(), rows, cols, true);
    for (std::size_t j = 0; j < features.size(); ++j) features[j] += outer[j];
  }
  for (std::size_t j = 0; j < features.size(); ++j) features[j] += head[j];

  enc.input = input;
  enc.dim = dim_;
  enc.query.resize(plane * dim_);
  enc.key.resize(plane * dim_);
  enc.score.resize(plane);
  enc.value.resize(plane);
  const Eigen::Map<const RowMatrix> fq(fq_.data(), dim_, width_), fk(fk_.data(), dim_, width_);
  const Eigen::Map<const Eigen::RowVectorXf> sz(sz_.data(), width_), sv(sv_.data(), width_);
  const auto n = static_cast<Eigen::Index>(plane);
  tbb::parallel_for(
      tbb::blocked_range<Eigen::Index>(0, n, 1024), [&](const tbb::blocked_range<Eigen::Index>& r) {
        const Eigen::Index b = r.begin(), len = r.end() - r.begin();
        const Eigen::Map<const RowMatrix, 0, Eigen::OuterStride<>> f(features.data() + b, width_,
                                                                     len, Eigen::OuterStride<>(n));
        Eigen::Map<Eigen::MatrixXf>(enc.query.data() + b * dim_, dim_, len).noalias() = fq * f;
        Eigen::Map<Eigen::MatrixXf>(enc.key.data() + b * dim_, dim_, len).noalias() = fk * f;
        Eigen::Map<Eigen::RowVectorXf>(enc.score.data() + b, len).noalias() = sz * f;
        Eigen::Map<Eigen::RowVectorXf>(enc.value.data() + b, len).noalias() = sv * f;
      });
}

float IlnModel::predict(const IlnEncoding& enc, double row, double col) const {
  const Neighbourhood n = neighbourhood(enc.input, row, col);
  bool usable[4];
  bool any = false;
  for (int t = 0; t < 4; ++t) {
    usable[t] = n.usable(t);
    any = any || usable[t];
  }
  if (!any) return 0.0F;
  const int d = enc.dim;
  // Each neighbour's query and key: its pixel's projections plus the offset's terms (float,
  // as PyTorch computes them).
  float q[kMaxDim][4], k[kMaxDim][4], z[4], v[4];  // [channel][neighbour]
  for (int t = 0; t < 4; ++t) {
    const auto o0 = static_cast<float>(n.d_row - (t / 2));
    const auto o1 = static_cast<float>(n.d_col - (t % 2));
    const std::size_t pixel = static_cast<std::size_t>(n.row[t]) * enc.input.layout.cols +
                              static_cast<std::size_t>(n.col[t]);
    const float* pq = enc.query.data() + pixel * d;
    const float* pk = enc.key.data() + pixel * d;
    for (int i = 0; i < d; ++i) {
      q[i][t] = pq[i] + (oq_[2 * i] * o0 + oq_[2 * i + 1] * o1 + cq_[i]);
      k[i][t] = pk[i] + (ok_[2 * i] * o0 + ok_[2 * i + 1] * o1 + ck_[i]);
    }
    z[t] = enc.score[pixel] + (oz_[0] * o0 + oz_[1] * o1 + cz_);
    v[t] = enc.value[pixel] + (ov_[0] * o0 + ov_[1] * o1 + cv_);
  }
  const float scale = 1.0F / std::sqrt(static_cast<float>(d));
  // Attention logits q_i . k_j: 16 independent sums (a short dependency chain per channel).
  float logits[4][4] = {};
  for (int c = 0; c < d; ++c) {
    for (int i = 0; i < 4; ++i) {
      for (int j = 0; j < 4; ++j) logits[i][j] += q[c][i] * k[c][j];
    }
  }
  float score[4];
  for (int i = 0; i < 4; ++i) {
    float logit[4];
    for (int j = 0; j < 4; ++j) logit[j] = logits[i][j] * scale;
    const float top = std::max(std::max(logit[0], logit[1]), std::max(logit[2], logit[3]));
    float sum = 0.0F, mixed = 0.0F;
    for (int j = 0; j < 4; ++j) {
      const float a = std::exp(logit[j] - top);
      sum += a;
      mixed += a * v[j];
    }
    score[i] = z[i] + mixed / sum + score_bias_;
  }
  if (prior_) {  // inverse-range bilinear interpolation as the starting point
    for (int t = 0; t < 4; ++t) {
      score[t] += std::log(std::max(static_cast<float>(n.weight[t]), kPriorMinWeight)) -
                  std::log(std::max(n.range[t], kPriorMinRange));
    }
  }
  // Softmax over the usable neighbours.
  float top = -std::numeric_limits<float>::infinity();
  for (int t = 0; t < 4; ++t) {
    if (usable[t]) top = std::max(top, score[t]);
  }
  float sum = 0.0F, blended = 0.0F;
  for (int t = 0; t < 4; ++t) {
    if (!usable[t]) continue;
    const float w = std::exp(score[t] - top);
    sum += w;
    blended += w * n.range[t];
  }
  return blended / sum;
}

RangeImage IlnModel::upsample(const RangeImage& input, const RangeLayout& output) const {
  Reused<IlnEncoding> workspace;  // like the encoder's activations
  IlnEncoding& enc = workspace.get();
  encode(input, enc);
  RangeImage out(output);
  tbb::parallel_for(tbb::blocked_range<int>(0, output.rows),
                    [&](const tbb::blocked_range<int>& rows) {
                      for (int r = rows.begin(); r != rows.end(); ++r) {
                        for (int c = 0; c < output.cols; ++c) {
                          const auto [row, col] = output.toLayout(input.layout, r, c);
                          out.at(r, c) = predict(enc, row, col);
                        }
                      }
                    });
  return out;
}

}  // namespace densemap::upsample
