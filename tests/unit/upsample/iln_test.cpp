// ILN inference in C++: the committed model against PyTorch's golden outputs, the
// weights file's errors, and the blend's invariants on constructed models.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <cmath>
#include <fstream>
#include <random>
#include <string>

#include "densemap/upsample/iln.hpp"
#include "densemap/upsample/interpolation.hpp"
#include "iln_weights.pb.h"

namespace densemap::upsample {
namespace {

/// A well-formed model of the given size with random weights (as PyTorch's state_dict names).
proto::IlnModel randomModel(int width, int blocks, int dim, unsigned seed, bool flat_score) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> normal(0.0F, 0.3F);
  proto::IlnModel m;
  m.set_version(1);
  m.set_width(width);
  m.set_blocks(blocks);
  m.set_dim(dim);
  m.set_max_range_m(80.0F);
  auto add = [&](const std::string& name, std::vector<unsigned> shape, bool zero = false) {
    proto::Tensor* t = m.add_tensors();
    t->set_name(name);
    unsigned size = 1;
    for (const unsigned s : shape) {
      t->add_shape(s);
      size *= s;
    }
    for (unsigned i = 0; i < size; ++i) t->add_data(zero ? 0.0F : normal(rng));
  };
  const auto w = static_cast<unsigned>(width), d = static_cast<unsigned>(dim);
  add("head.weight", {w, 1, 3, 3});
  add("head.bias", {w});
  for (int b = 0; b < blocks; ++b) {
    for (const char* c : {".conv1", ".conv2"}) {
      add("body." + std::to_string(b) + c + ".weight", {w, w, 3, 3});
      add("body." + std::to_string(b) + c + ".bias", {w});
    }
  }
  add("embed.weight", {d, w + 2});
  add("embed.bias", {d});
  for (const char* n : {"q", "k", "v"}) {
    add(std::string(n) + ".weight", {d, d});
    add(std::string(n) + ".bias", {d});
  }
  add("score.weight", {1, d}, flat_score);
  add("score.bias", {1});
  return m;
}

RangeImage randomImage(int rows, int cols, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> range(1.0F, 60.0F);
  std::bernoulli_distribution hit(0.85);
  RangeImage image(RangeLayout{.rows = rows, .cols = cols});
  for (float& r : image.range) r = hit(rng) ? range(rng) : 0.0F;
  return image;
}

Expected<IlnModel> parsed(const proto::IlnModel& m) {
  return IlnModel::parse(m.SerializeAsString(), "test model");
}

TEST(Iln, MatchesPyTorchGoldenOutputs) {
  const auto model = IlnModel::load(DENSEMAP_ILN_MODEL);
  ASSERT_TRUE(model) << model.error().message;
  std::ifstream in(DENSEMAP_ILN_GOLDEN, std::ios::binary);
  ASSERT_TRUE(in) << "missing " << DENSEMAP_ILN_GOLDEN;
  proto::IlnGolden golden;
  ASSERT_TRUE(golden.ParseFromIstream(&in));
  RangeImage image(RangeLayout{.rows = static_cast<int>(golden.rows()),
                               .cols = static_cast<int>(golden.cols())});
  ASSERT_EQ(static_cast<std::size_t>(golden.image_size()), image.range.size());
  std::copy(golden.image().begin(), golden.image().end(), image.range.begin());
  ASSERT_EQ(golden.queries_size(), 2 * golden.ranges_size());
  ASSERT_GT(golden.ranges_size(), 100);
  const IlnEncoding enc = model->encode(image);
  double worst = 0.0;
  for (int i = 0; i < golden.ranges_size(); ++i) {
    const float got = model->predict(enc, golden.queries(2 * i), golden.queries(2 * i + 1));
    worst = std::max(worst, std::abs(static_cast<double>(got) - golden.ranges(i)));
    EXPECT_NEAR(got, golden.ranges(i), 1e-4) << "query " << i;
  }
  RecordProperty("worst_abs_error_m", std::to_string(worst));
}

TEST(Iln, CommittedModelUpsamplesWithinTheNeighbourRanges) {
  const auto model = IlnModel::load(DENSEMAP_ILN_MODEL);
  ASSERT_TRUE(model) << model.error().message;
  const RangeImage input = randomImage(16, 128, 5);
  const RangeImage out = model->upsample(input, RangeLayout{.rows = 61, .cols = 256});
  const IlnEncoding enc = model->encode(input);
  for (int r = 0; r < 61; ++r) {
    for (int c = 0; c < 256; ++c) {
      const auto [row, col] = out.layout.toLayout(input.layout, r, c);
      const Neighbourhood n = neighbourhood(input, row, col);
      float lo = 1e9F, hi = 0.0F;
      for (int t = 0; t < 4; ++t) {
        if (n.usable(t)) lo = std::min(lo, n.range[t]), hi = std::max(hi, n.range[t]);
      }
      const float got = out.at(r, c);
      EXPECT_EQ(got, model->predict(enc, row, col));
      if (hi == 0.0F) {
        EXPECT_EQ(got, 0.0F);
      } else {  // a convex blend of the usable neighbours
        EXPECT_GE(got, lo * (1 - 1e-6F));
        EXPECT_LE(got, hi * (1 + 1e-6F));
      }
    }
  }
}

TEST(Iln, FlatScoresAverageTheUsableNeighbours) {
  const auto model = parsed(randomModel(4, 1, 4, 1, /*flat_score=*/true));
  ASSERT_TRUE(model) << model.error().message;
  const RangeImage input = randomImage(8, 32, 2);
  const IlnEncoding enc = model->encode(input);
  for (const auto& [row, col] : {std::pair{0.0, 0.0}, {2.3, 7.9}, {6.5, 31.5}, {7.0, 12.25}}) {
    const Neighbourhood n = neighbourhood(input, row, col);
    double sum = 0.0;
    int count = 0;
    for (int t = 0; t < 4; ++t) {
      if (n.usable(t)) sum += n.range[t], ++count;
    }
    EXPECT_NEAR(model->predict(enc, row, col), count ? sum / count : 0.0, 1e-4);
  }
}

TEST(Iln, AQueryOnAPixelLineNeverReachesAcrossIt) {
  const auto model = IlnModel::load(DENSEMAP_ILN_MODEL);
  ASSERT_TRUE(model) << model.error().message;
  RangeImage input = randomImage(8, 32, 3);
  for (int c = 0; c < 32; ++c) input.at(3, c) = 0.0F;  // a row without returns
  for (int c = 0; c < 32; ++c) input.at(4, c) = 10.0F + c;
  const IlnEncoding enc = model->encode(input);
  // On row 3 only row 3's pixels can be blended (as bilinear does): no range from row 4.
  EXPECT_EQ(model->predict(enc, 3.0, 5.5), 0.0F);
  EXPECT_EQ(interpolate(input, 3.0, 5.5, Interpolation::kBilinear), 0.0F);
  // On row 4 it is row 4's own blend, between its two pixels.
  const float on_row4 = model->predict(enc, 4.0, 5.5);
  EXPECT_GE(on_row4, 15.0F);
  EXPECT_LE(on_row4, 16.0F);
  // On a column line (col 7.0) only column 7 is used.
  EXPECT_EQ(model->predict(enc, 3.5, 7.0), 17.0F);
}

TEST(Iln, ResultDoesNotDependOnTheThreadCountOrRepeat) {
  const auto model = parsed(randomModel(8, 2, 8, 3, false));
  ASSERT_TRUE(model);
  const RangeImage input = randomImage(16, 256, 4);
  const RangeLayout out{.rows = 64, .cols = 256};
  RangeImage a, b;
  tbb::task_arena(1).execute([&] { a = model->upsample(input, out); });
  tbb::task_arena(2).execute([&] { b = model->upsample(input, out); });
  EXPECT_EQ(a.range, b.range);
  EXPECT_EQ(model->upsample(input, out).range, a.range);
  EXPECT_GT(a.returns(), a.range.size() / 2);
}

TEST(Iln, UpsampleDispatchesToTheModel) {
  const auto model = parsed(randomModel(4, 1, 4, 6, false));
  ASSERT_TRUE(model);
  const RangeImage input = randomImage(16, 64, 7);
  const RangeLayout out{.rows = 64, .cols = 64};
  EXPECT_EQ(upsample(input, out, Interpolation::kIln, &*model).range,
            model->upsample(input, out).range);
  UpsampleOptions options{
      .input = input.layout, .output = out, .method = Interpolation::kIln, .iln = nullptr};
  EXPECT_FALSE(options.validate());
  options.iln = std::make_shared<IlnModel>(*model);
  EXPECT_TRUE(options.validate());
  EXPECT_EQ(*parseInterpolation("iln"), Interpolation::kIln);
  EXPECT_EQ(interpolationName(Interpolation::kIln), "iln");
}

TEST(IlnWeights, MissingFileIsAClearError) {
  const auto model = IlnModel::load("/nonexistent/iln.pb");
  ASSERT_FALSE(model);
  EXPECT_NE(model.error().message.find("cannot open"), std::string::npos);
}

TEST(IlnWeights, TruncatedOrGarbageBytesAreRejected) {
  const std::string bytes = randomModel(4, 1, 4, 8, false).SerializeAsString();
  ASSERT_TRUE(IlnModel::parse(bytes, "full"));
  int rejected = 0;
  for (const std::size_t keep : {std::size_t{0}, std::size_t{1}, std::size_t{7}, bytes.size() / 3,
                                 bytes.size() / 2, bytes.size() - 5, bytes.size() - 1}) {
    const auto model = IlnModel::parse(std::string_view(bytes).substr(0, keep), "cut");
    EXPECT_FALSE(model) << "kept " << keep << " of " << bytes.size() << " bytes";
    if (!model) {
      EXPECT_NE(model.error().message.find("cut"), std::string::npos);
      ++rejected;
    }
  }
  EXPECT_EQ(rejected, 7);
  EXPECT_FALSE(IlnModel::parse("this is not a protobuf at all \xff\xff\xff", "garbage"));
}

TEST(IlnWeights, WrongShapesAndMissingTensorsAreNamed) {
  {
    proto::IlnModel m = randomModel(4, 1, 4, 9, false);
    m.mutable_tensors(2)->set_shape(1, 3);  // body.0.conv1.weight: (4, 3, 3, 3)
    const auto model = parsed(m);
    ASSERT_FALSE(model);
    EXPECT_NE(model.error().message.find("body.0.conv1.weight"), std::string::npos);
    EXPECT_NE(model.error().message.find("(4, 3, 3, 3)"), std::string::npos);
  }
  {
    proto::IlnModel m = randomModel(4, 1, 4, 9, false);
    m.set_blocks(2);  // the file holds one block
    const auto model = parsed(m);
    ASSERT_FALSE(model);
    EXPECT_NE(model.error().message.find("'body.1.conv1.weight' is missing"), std::string::npos);
  }
  {
    proto::IlnModel m = randomModel(4, 1, 4, 9, false);
    m.mutable_tensors(0)->mutable_data()->RemoveLast();
    const auto model = parsed(m);
    ASSERT_FALSE(model);
    EXPECT_NE(model.error().message.find("holds 35 values"), std::string::npos);
  }
  {
    proto::IlnModel m = randomModel(4, 1, 4, 9, false);
    m.set_blocks(0);  // body.0.* are left over
    const auto model = parsed(m);
    ASSERT_FALSE(model);
    EXPECT_NE(model.error().message.find("unexpected tensor"), std::string::npos);
  }
  {
    proto::IlnModel m = randomModel(4, 1, 4, 9, false);
    m.mutable_tensors(1)->set_data(0, std::nanf(""));
    EXPECT_FALSE(parsed(m));
  }
  {
    proto::IlnModel m = randomModel(4, 1, 4, 9, false);
    m.set_version(2);
    EXPECT_FALSE(parsed(m));
    m.set_version(1);
    m.set_dim(100000);
    EXPECT_FALSE(parsed(m));
    m.set_dim(4);
    m.set_max_range_m(-1.0F);
    EXPECT_FALSE(parsed(m));
  }
}

}  // namespace
}  // namespace densemap::upsample
