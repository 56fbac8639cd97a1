#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <map>

#include "densemap/io/file_bytes.hpp"
#include "densemap/upsample/iln.hpp"
#include "iln_limits.hpp"
#include "iln_weights.pb.h"

// Reading an ILN weights file (idl/iln_weights.proto): the header's checks, every tensor by
// name and shape, and the query stage's linear layers folded (IlnLoader, IlnModel's friend).
namespace densemap::upsample {
namespace {

using RowMatrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using RowMatrixD = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using Linear = std::map<std::string, std::vector<float>>;

constexpr std::size_t kMaxFileBytes = std::size_t{256} << 20;
constexpr int kMaxWidth = 512;
constexpr int kMaxBlocks = 64;

/// The model's tensors by name, each checked for its expected shape when taken.
class Tensors {
 public:
  Tensors(const proto::IlnModel& model, std::string what) : what_(std::move(what)) {
    for (const auto& t : model.tensors()) tensors_.emplace(t.name(), &t);
  }

  Expected<std::vector<float>> take(const std::string& name, std::vector<std::uint32_t> shape) {
    const auto it = tensors_.find(name);
    if (it == tensors_.end()) return makeError(what_ + ": tensor '" + name + "' is missing");
    const proto::Tensor& t = *it->second;
    tensors_.erase(it);
    if (!std::equal(shape.begin(), shape.end(), t.shape().begin(), t.shape().end())) {
      return makeError(what_ + ": tensor '" + name + "' has shape " + describe(t.shape()) +
                       ", the model needs " + describe(shape));
    }
    std::size_t size = 1;
    for (const std::uint32_t s : shape) size *= s;
    if (static_cast<std::size_t>(t.data_size()) != size) {
      return makeError(what_ + ": tensor '" + name + "' holds " + std::to_string(t.data_size()) +
                       " values, its shape needs " + std::to_string(size));
    }
    for (const float v : t.data()) {
      if (!std::isfinite(v)) return makeError(what_ + ": tensor '" + name + "' is not finite");
    }
    taken_ += size;
    return std::vector<float>(t.data().begin(), t.data().end());
  }

  /// An error naming a tensor the model does not use (a file for another architecture).
  Expected<void> finish() const {
    if (!tensors_.empty()) {
      return makeError(what_ + ": unexpected tensor '" + tensors_.begin()->first + "'");
    }
    return {};
  }
  [[nodiscard]] std::size_t taken() const { return taken_; }

 private:
  template <class Shape>
  static std::string describe(const Shape& shape) {
    std::string out = "(";
    for (const auto s : shape) out += (out.size() > 1 ? ", " : "") + std::to_string(s);
    return out + ")";
  }

  std::string what_;
  std::map<std::string, const proto::Tensor*> tensors_;
  std::size_t taken_ = 0;
};

RowMatrixD toMatrix(const std::vector<float>& data, int rows, int cols) {
  return Eigen::Map<const RowMatrix>(data.data(), rows, cols).cast<double>();
}

std::vector<float> toVector(const RowMatrixD& m) {
  std::vector<float> out(static_cast<std::size_t>(m.size()));
  Eigen::Map<RowMatrix>(out.data(), m.rows(), m.cols()) = m.cast<float>();
  return out;
}

}  // namespace

struct IlnLoader {
  /// Version, sizes, range and prior.
  static Expected<void> header(const proto::IlnModel& m, const std::string& what, IlnModel& model) {
    if (m.version() != 1) {
      return makeError(what + " has format version " + std::to_string(m.version()) +
                       "; this densemap reads version 1");
    }
    const int w = static_cast<int>(m.width()), b = static_cast<int>(m.blocks());
    const int d = static_cast<int>(m.dim());
    if (!m.has_width() || w < 1 || w > kMaxWidth || !m.has_blocks() || b > kMaxBlocks ||
        !m.has_dim() || d < 1 || d > kMaxDim) {
      return makeError(what + ": width, blocks and dim must be set (width 1.." +
                       std::to_string(kMaxWidth) + ", blocks 0.." + std::to_string(kMaxBlocks) +
                       ", dim 1.." + std::to_string(kMaxDim) + ")");
    }
    if (!(m.max_range_m() > 0.0F) || !std::isfinite(m.max_range_m())) {
      return makeError(what + ": max_range_m must be a positive number");
    }
    if (m.prior() != "" && m.prior() != "inverse_bilinear") {
      return makeError(what + ": unknown prior '" + m.prior() + "' ('' or inverse_bilinear)");
    }
    model.prior_ = m.prior() == "inverse_bilinear";
    model.width_ = w;
    model.blocks_ = b;
    model.dim_ = d;
    model.max_range_ = m.max_range_m();
    model.provenance_ = m.provenance();
    return {};
  }

  /// The encoder: the head and two convolutions per residual block.
  static Expected<void> convolutions(Tensors& tensors, IlnModel& model) {
    const int w = model.width_;
    const auto uw = static_cast<std::uint32_t>(w);
    auto conv = [&](const std::string& name, int in) -> Expected<IlnModel::Conv> {
      IlnModel::Conv c;
      c.in = in;
      c.out = w;
      auto weight = tensors.take(name + ".weight", {uw, static_cast<std::uint32_t>(in), 3, 3});
      if (!weight) return std::unexpected(weight.error());
      auto bias = tensors.take(name + ".bias", {uw});
      if (!bias) return std::unexpected(bias.error());
      c.weight = std::move(*weight);
      c.bias = std::move(*bias);
      return c;
    };
    auto head = conv("head", 1);
    if (!head) return std::unexpected(head.error());
    model.head_ = std::move(*head);
    for (int i = 0; i < model.blocks_; ++i) {
      for (const char* part : {".conv1", ".conv2"}) {
        auto c = conv("body." + std::to_string(i) + part, w);
        if (!c) return std::unexpected(c.error());
        model.body_.push_back(std::move(*c));
      }
    }
    return {};
  }

  /// The query stage's linear layers (embedding, q, k, v, score).
  static Expected<Linear> linearLayers(Tensors& tensors, int w, int d) {
    const auto uw = static_cast<std::uint32_t>(w), ud = static_cast<std::uint32_t>(d);
    Linear linear;
    const std::pair<const char*, std::vector<std::uint32_t>> shapes[] = {
        {"embed.weight", {ud, uw + 2}}, {"embed.bias", {ud}},
        {"q.weight", {ud, ud}},         {"q.bias", {ud}},
        {"k.weight", {ud, ud}},         {"k.bias", {ud}},
        {"v.weight", {ud, ud}},         {"v.bias", {ud}},
        {"score.weight", {1, ud}},      {"score.bias", {1}}};
    for (const auto& [name, shape] : shapes) {
      auto t = tensors.take(name, shape);
      if (!t) return std::unexpected(t.error());
      linear[name] = std::move(*t);
    }
    return linear;
  }

  /// Folds the linear layers of the query stage. With z = E_f f + E_o o + e (the embedding of a
  /// neighbour's feature f and offset o), q = Q z + q0, k = K z + k0, v = V z + v0 and the
  /// score s . (z + sum_j a_j v_j) + s0, everything but the attention is linear in (f, o):
  ///   q = (Q E_f) f + (Q E_o) o + (Q e + q0), likewise k; s . z and s . v are scalars.
  static void foldQueryStage(Linear& linear, IlnModel& model) {
    const int w = model.width_, d = model.dim_;
    const RowMatrixD embed = toMatrix(linear["embed.weight"], d, w + 2);
    const RowMatrixD ef = embed.leftCols(w), eo = embed.rightCols(2);
    const Eigen::VectorXd e = toMatrix(linear["embed.bias"], d, 1);
    const RowMatrixD q = toMatrix(linear["q.weight"], d, d), k = toMatrix(linear["k.weight"], d, d);
    const RowMatrixD v = toMatrix(linear["v.weight"], d, d);
    const Eigen::VectorXd q0 = toMatrix(linear["q.bias"], d, 1);
    const Eigen::VectorXd k0 = toMatrix(linear["k.bias"], d, 1);
    const Eigen::VectorXd v0 = toMatrix(linear["v.bias"], d, 1);
    const RowMatrixD s = toMatrix(linear["score.weight"], 1, d);
    model.fq_ = toVector(q * ef);
    model.fk_ = toVector(k * ef);
    model.oq_ = toVector(q * eo);
    model.ok_ = toVector(k * eo);
    model.cq_ = toVector(q * e + q0);
    model.ck_ = toVector(k * e + k0);
    model.sz_ = toVector(s * ef);
    model.sv_ = toVector(s * v * ef);
    const RowMatrixD oz = s * eo, ov = s * v * eo;
    for (int i = 0; i < 2; ++i) {
      model.oz_[i] = static_cast<float>(oz(0, i));
      model.ov_[i] = static_cast<float>(ov(0, i));
    }
    model.cz_ = static_cast<float>((s * e)(0, 0));
    model.cv_ = static_cast<float>((s * (v * e + v0))(0, 0));
    model.score_bias_ = linear["score.bias"][0];
  }
};

Expected<IlnModel> IlnModel::load(const std::string& path) {
  auto bytes = readFileBytes(path, kMaxFileBytes);
  if (!bytes) return makeError("cannot open ILN weights file " + bytes.error().message);
  return parse(*bytes, "ILN weights file '" + path + "'");
}

Expected<IlnModel> IlnModel::parse(std::string_view bytes, const std::string& what) {
  proto::IlnModel m;
  if (bytes.empty() || !m.ParseFromArray(bytes.data(), static_cast<int>(bytes.size()))) {
    return makeError(what + " is not an ILN weights file (empty, truncated or corrupt)");
  }
  IlnModel model;
  if (auto ok = IlnLoader::header(m, what, model); !ok) return std::unexpected(ok.error());
  Tensors tensors(m, what);
  if (auto ok = IlnLoader::convolutions(tensors, model); !ok) return std::unexpected(ok.error());
  auto linear = IlnLoader::linearLayers(tensors, model.width_, model.dim_);
  if (!linear) return std::unexpected(linear.error());
  if (auto done = tensors.finish(); !done) return std::unexpected(done.error());
  model.parameters_ = tensors.taken();
  IlnLoader::foldQueryStage(*linear, model);
  return model;
}

}  // namespace densemap::upsample
