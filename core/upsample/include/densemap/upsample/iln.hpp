#pragma once

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/upsample/range_image.hpp"

namespace densemap::upsample {

/// An input image run through the ILN encoder once, ready for any number of queries: per
/// pixel, the query and key projections of its local feature and two scalar projections.
struct IlnEncoding {
  RangeImage input;
  int dim = 0;
  std::vector<float> query;  // pixels x dim
  std::vector<float> key;    // pixels x dim
  std::vector<float> score;  // pixels: score-weighted local feature
  std::vector<float> value;  // pixels: score-weighted value
};

/// The Implicit LiDAR Network (dissertation Ch. 4, Eq. 4.3) at inference time: an EDSR-style
/// encoder (3x3 head convolution, residual blocks of two 3x3 convolutions, a global skip), then
/// for each query laser the 4 input pixels around it, each with its feature and the query's
/// offset from it, one self-attention layer across the 4, a linear score, and softmax weights
/// over the neighbours that have returns; the output is the weighted sum of their ranges.
/// Optionally (the "inverse_bilinear" prior) each score starts from log(bilinear weight) -
/// log(range), so the network learns corrections to inverse-range bilinear interpolation.
/// Weights come from `tools/iln/iln.py export` (schema idl/iln_weights.proto); inference is
/// Eigen + TBB, matching PyTorch's output to float rounding.
class IlnModel {
 public:
  /// Reads a weights file; clear errors for a missing, truncated or mismatched file.
  [[nodiscard]] static Expected<IlnModel> load(const std::string& path);
  /// The same from the file's bytes; `what` names the source in errors.
  [[nodiscard]] static Expected<IlnModel> parse(std::string_view bytes, const std::string& what);

  [[nodiscard]] int width() const { return width_; }
  [[nodiscard]] int blocks() const { return blocks_; }
  [[nodiscard]] int dim() const { return dim_; }
  [[nodiscard]] std::size_t parameters() const;
  [[nodiscard]] const std::string& provenance() const { return provenance_; }

  /// Runs the encoder on `input` (any grid of at least 2 rows), in parallel.
  [[nodiscard]] IlnEncoding encode(const RangeImage& input) const;
  /// The same into `encoding`, reusing its buffers.
  void encode(const RangeImage& input, IlnEncoding& encoding) const;
  /// The range at a continuous (row, col) of the encoded input's grid; 0 when none of the 4
  /// neighbours has a return.
  [[nodiscard]] float predict(const IlnEncoding& encoding, double row, double col) const;
  /// `input` resampled to `output`'s grid (same field of view frame), in parallel.
  [[nodiscard]] RangeImage upsample(const RangeImage& input, const RangeLayout& output) const;

 private:
  friend struct IlnLoader;  // reads a weights file into the members (iln_load.cpp)
  struct Conv {
    int in = 0, out = 0;
    std::vector<float> weight;  // out x (in * 9), PyTorch's (out, in, 3, 3) order
    std::vector<float> bias;
  };
  /// `x` (in x rows x cols) convolved into `y` (out x rows x cols), zero padding 1, optionally
  /// through a ReLU first.
  static void convolve(const Conv& conv, const float* x, float* y, int rows, int cols,
                       bool relu_input);

  int width_ = 0, blocks_ = 0, dim_ = 0;
  bool prior_ = false;  // inverse_bilinear (see idl/iln_weights.proto)
  float max_range_ = 1.0F;
  std::string provenance_;
  Conv head_;
  std::vector<Conv> body_;  // two per block
  // Folded head of the query stage (see iln.cpp): per pixel, query = fq * f, key = fk * f,
  // score = sz . f, value = sv . f; per neighbour, offsets add oq/ok/oz/ov * offset + constants.
  std::vector<float> fq_, fk_;  // dim x width
  std::vector<float> sz_, sv_;  // width
  std::vector<float> oq_, ok_;  // dim x 2
  float oz_[2] = {}, ov_[2] = {};
  std::vector<float> cq_, ck_;  // dim
  float cz_ = 0.0F, cv_ = 0.0F, score_bias_ = 0.0F;
  std::size_t parameters_ = 0;
};

}  // namespace densemap::upsample
