// The neural codec's numerical core (neural_net.h): the MLP's gradients against central finite
// differences, Adam and lazy Adam against the update written out, the trainer's reduced gradient
// against the double network, a fit of synthetic lobes, the same bits for 1 and 2 threads and for
// blocks computed in parts, the decoder's inference path against Forward, cancelling, refused
// input, and finite results at grazing directions.
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

#include <fmt/format.h>

#include "libbtf/compress/neural_net.h"
#include "libbtf/core/error.h"
#include "tests/compress/neural_lobes.h"

namespace btf {
namespace {

using NetD = BasicNeuralNet<double>;
constexpr Activation kActivations[] = {Activation::kRelu, Activation::kLeakyRelu, Activation::kSoftplus,
                                       Activation::kSilu};

Eigen::MatrixXd RandomMatrix(Eigen::Index rows, Eigen::Index cols, std::uint64_t seed, double scale) {
  Eigen::MatrixXd m(rows, cols);
  for (Eigen::Index i = 0; i < m.size(); ++i) m.data()[i] = scale * (2 * test::LobeHash(seed * 1000003 + i) - 1);
  return m;
}

// loss = sum(R .* net(X)): its gradient with respect to the output is R.
double WeightedOutput(const NetD& net, const Eigen::MatrixXd& X, const Eigen::MatrixXd& R) {
  NetD::Workspace ws;
  return net.Forward(X, ws).cwiseProduct(R).sum();
}

// Smallest |pre-activation| of any hidden unit over the batch (ReLU's kink is at 0).
double SmallestPreActivation(const NetD& net, const Eigen::MatrixXd& X) {
  NetD::Workspace ws;
  net.Forward(X, ws);
  double m = std::numeric_limits<double>::infinity();
  for (int l = 0; l + 1 < net.layers(); ++l) m = std::min(m, ws.z[l].cwiseAbs().minCoeff());
  return m;
}

TEST(NeuralNet, EveryGradientMatchesCentralDifferencesInDouble) {
  // Central differences with h = 1e-6 in double: truncation error h^2 |f'''| / 6 ~ 1e-12 (the
  // nets' third derivatives are O(1) here) and rounding eps |f| / h ~ 1e-16 * 10 / 1e-6 = 1e-9,
  // so 1e-8 (absolute, the gradients are O(1)) fails only on a wrong gradient; measured worst
  // 8e-10 (recorded per activation). ReLU and leaky ReLU have a kink at 0: the test asserts that
  // no pre-activation lies within 1e-4 >> h of it.
  const double h = 1e-6, tolerance = 1e-8;
  for (const Activation act : kActivations) {
    NetD net(NeuralNetShape{6, {5, 4}, 3, act}, 7);
    // Non-zero biases, so that their gradient paths are exercised with general values.
    for (int l = 0; l < net.layers(); ++l)
      for (Eigen::Index k = 0; k < net.bias(l).size(); ++k)
        net.parameters()[net.bias_offset(l) + k] = 0.3 * (2 * test::LobeHash(100 * l + k) - 1);
    const Eigen::MatrixXd X = RandomMatrix(6, 9, 1, 1.5), R = RandomMatrix(3, 9, 2, 1.0);
    ASSERT_GT(SmallestPreActivation(net, X), 1e-4) << ActivationName(act);
    NetD::Workspace ws;
    net.Forward(X, ws);
    std::vector<double> grad(net.parameter_count(), 0.0);
    Eigen::MatrixXd dX;
    net.Backward(X, R, ws, grad.data(), &dX);
    double worst = 0;
    for (Eigen::Index k = 0; k < net.parameter_count(); ++k) {  // every weight and bias
      NetD plus = net, minus = net;
      plus.parameters()[k] += h;
      minus.parameters()[k] -= h;
      const double fd = (WeightedOutput(plus, X, R) - WeightedOutput(minus, X, R)) / (2 * h);
      worst = std::max(worst, std::abs(fd - grad[k]));
      EXPECT_NEAR(grad[k], fd, tolerance) << ActivationName(act) << " parameter " << k;
    }
    for (Eigen::Index k = 0; k < X.size(); ++k) {  // every input (the latents among them)
      Eigen::MatrixXd xp = X, xm = X;
      xp.data()[k] += h;
      xm.data()[k] -= h;
      const double fd = (WeightedOutput(net, xp, R) - WeightedOutput(net, xm, R)) / (2 * h);
      worst = std::max(worst, std::abs(fd - dX.data()[k]));
      EXPECT_NEAR(dX.data()[k], fd, tolerance) << ActivationName(act) << " input " << k;
    }
    RecordProperty(std::string(ActivationName(act)) + "_worst_abs_error", fmt::format("{:.3g}", worst));
  }
}

TEST(NeuralNet, FloatGradientIsTheDoubleOneToFloatRounding) {
  // Same parameters and data in float and double; float sums of <= 32 products round at
  // ~32 * 6e-8 relative to the sum of |terms|, so 1e-4 of the gradient's largest entry is loose
  // enough for the 3 layers and tight enough to catch any wrong term.
  for (const Activation act : kActivations) {
    const NeuralNetShape shape{12, {32, 32}, 3, act};
    NeuralNet f(shape, 3);
    NetD d(shape, 3);
    for (Eigen::Index k = 0; k < f.parameter_count(); ++k) d.parameters()[k] = f.parameters()[k];
    const Eigen::MatrixXd X = RandomMatrix(12, 64, 4, 1.0), R = RandomMatrix(3, 64, 5, 1.0);
    const Eigen::MatrixXf Xf = X.cast<float>(), Rf = R.cast<float>();
    NeuralNet::Workspace wf;
    NetD::Workspace wd;
    f.Forward(Xf, wf);
    d.Forward(X, wd);
    std::vector<float> gf(f.parameter_count(), 0.f);
    std::vector<double> gd(d.parameter_count(), 0.0);
    Eigen::MatrixXf dXf;
    Eigen::MatrixXd dXd;
    f.Backward(Xf, Rf, wf, gf.data(), &dXf);
    d.Backward(X, R, wd, gd.data(), &dXd);
    double scale = 0;
    for (const double g : gd) scale = std::max(scale, std::abs(g));
    for (Eigen::Index k = 0; k < f.parameter_count(); ++k)
      ASSERT_NEAR(gf[k], gd[k], 1e-4 * scale) << ActivationName(act) << " parameter " << k;
    EXPECT_LE((dXf.cast<double>() - dXd).cwiseAbs().maxCoeff(), 1e-4 * dXd.cwiseAbs().maxCoeff()) << ActivationName(act);
  }
}

TEST(NeuralNet, ExtremePreActivationsStayFinite) {
  // Inputs of +-1e3 drive pre-activations to several thousand: exp overflows inside softplus and
  // SiLU unless they are written for it.
  for (const Activation act : kActivations) {
    NeuralNet net(NeuralNetShape{4, {16, 16}, 3, act}, 11);
    Eigen::MatrixXf X = RandomMatrix(4, 32, 6, 1.0).cast<float>() * 1e3f;
    NeuralNet::Workspace ws;
    const Eigen::MatrixXf Y = net.Forward(X, ws);
    EXPECT_TRUE(Y.allFinite()) << ActivationName(act);
    std::vector<float> g(net.parameter_count(), 0.f);
    Eigen::MatrixXf dX;
    net.Backward(X, Eigen::MatrixXf::Ones(3, 32), ws, g.data(), &dX);
    for (const float v : g) ASSERT_TRUE(std::isfinite(v)) << ActivationName(act);
    EXPECT_TRUE(dX.allFinite()) << ActivationName(act);
  }
}

TEST(NeuralNet, InferAgreesWithForward) {
  // Infer (the decoder's path: lane-major groups, SiLU by its own exp and reciprocal) against
  // Forward on the same samples: 37 columns (two full groups of 16 and a partial one on AVX2),
  // layer 0 given as its product p (row stride 40 > 37) and the bias as the shift. Both sum
  // <= 32 float products (~32 * 6e-8 relative to the sum of |terms|) and SiLU differs by <= 4e-7,
  // so 1e-5 of the outputs' largest magnitude; scale 1e3: pre-activations of thousands, where
  // the clamped exp must still give z or 0.
  for (const Activation act : kActivations)
    for (const double scale : {1.0, 1e3}) {
      NeuralNet net(NeuralNetShape{12, {32, 24}, 3, act}, 7);
      const Eigen::MatrixXf X = (RandomMatrix(12, 37, 8, 1.0) * scale).cast<float>();
      NeuralNet::Workspace ws;
      const Eigen::MatrixXf Y = net.Forward(X, ws);
      Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> p(32, 40);
      p.leftCols(37) = net.weight(0) * X;
      Eigen::MatrixXf out(3, 37);
      net.Infer(p.data(), 40, net.bias(0).data(), 37, out.data(), ws);
      ASSERT_TRUE(out.allFinite()) << ActivationName(act) << " scale " << scale;
      EXPECT_LE((out - Y).cwiseAbs().maxCoeff(), 1e-5f * Y.cwiseAbs().maxCoeff())
          << ActivationName(act) << " scale " << scale;
    }
}

TEST(NeuralAdam, DenseAndLazyUpdatesAreAdamWrittenOut) {
  AdamOptions o;
  Adam adam(2, o);
  LazyAdam lazy(3, 2, o);
  float p[2] = {1.f, -2.f}, rows[3][2] = {{1.f, -2.f}, {5.f, 5.f}, {1.f, -2.f}};
  double ref[2] = {1, -2}, m[2] = {0, 0}, v[2] = {0, 0};
  const float grads[3][2] = {{0.5f, -1.f}, {0.1f, 2.f}, {-0.3f, 0.f}};
  for (int t = 1; t <= 3; ++t) {
    adam.Step(p, grads[t - 1], 0.01);
    lazy.StepRow(0, rows[0], grads[t - 1], 0.01);
    for (int i = 0; i < 2; ++i) {
      m[i] = o.beta1 * m[i] + (1 - o.beta1) * grads[t - 1][i];
      v[i] = o.beta2 * v[i] + (1 - o.beta2) * double(grads[t - 1][i]) * grads[t - 1][i];
      const double mh = m[i] / (1 - std::pow(o.beta1, t)), vh = v[i] / (1 - std::pow(o.beta2, t));
      ref[i] -= 0.01 * mh / (std::sqrt(vh) + o.epsilon);
      // Float moments and parameters: a few float roundings of values ~1.
      EXPECT_NEAR(p[i], ref[i], 1e-6) << "step " << t;
      EXPECT_EQ(rows[0][i], p[i]) << "the lazy row follows dense Adam's arithmetic";
    }
  }
  // Row 1 was never touched: unchanged. Row 2's first update comes late but is a full Adam step:
  // with one update, m_hat = g and v_hat = g^2, so it moves by lr sign(g) (where g != 0).
  EXPECT_EQ(rows[1][0], 5.f);
  EXPECT_EQ(lazy.updates(1), 0);
  lazy.StepRow(2, rows[2], grads[0], 0.01);
  EXPECT_NEAR(rows[2][0], 1 - 0.01, 1e-6);
  EXPECT_NEAR(rows[2][1], -2 + 0.01, 1e-6);
  EXPECT_EQ(lazy.updates(2), 1);
}

// Trains on one thread while in scope. The results are the same with any number of threads
// (SameBitsForOneAndTwoThreadsAndForBlocksComputedInParts), and a team of two waits at every
// step for a thread that ctest -j's other tests keep off the CPU: the lobe fit took 6 s instead
// of 1.5 s on a loaded 2-core machine.
struct OneThread {
  int saved = omp_get_max_threads();
  OneThread() { omp_set_num_threads(1); }
  ~OneThread() { omp_set_num_threads(saved); }
};

NeuralTrainOptions SmallOptions() {
  NeuralTrainOptions o;
  o.batch = 1024;
  o.block = 256;
  o.steps = 20;
  o.seed = 5;
  return o;
}

// The training loss of NeuralTrainOptions::linear_loss in double: per value
// (1 - w) (y - t)^2 + w (e^y - e^t)^2 / S, S the mean of e^2t over all samples; its mean over the
// values, and d(mean)/dY in dY.
double TrainingLoss(const Eigen::MatrixXd& Y, const Eigen::MatrixXd& T, double w, double S, Eigen::MatrixXd* dY) {
  const Eigen::ArrayXXd r = (Y - T).array(), ey = Y.array().exp(), rl = ey - T.array().exp();
  const double values = double(Y.size());
  if (dY) *dY = ((2 * (1 - w)) * r + (2 * w / S) * rl * ey).matrix() / values;
  return ((1 - w) * r.square() + (w / S) * rl.square()).sum() / values;
}

TEST(NeuralTrainer, StepGradientIsTheLossGradientInDoubleAndByCentralDifferences) {
  // The trainer's reduced step gradient (float blocks summed in double, divided by the value
  // count) against the double network's gradient of the same batch's loss, built here from the
  // trainer's own latents, encodings and batch, for the log-domain loss (w = 0), the linear one
  // (w = 1) and a mix; and that double gradient against central differences of the loss.
  const NeuralSamples s = test::LobeSamples(16, 100, 1);
  double S = 0;
  for (const float t : s.target) S += std::exp(2.0 * double(t));
  S /= double(s.target.size());
  for (const double w : {0.0, 0.5, 1.0}) {
    SCOPED_TRACE(fmt::format("linear_loss {}", w));
    NeuralTrainOptions o = SmallOptions();
    o.encoding.half_vector = true;
    o.activation = Activation::kSilu;
    o.linear_loss = w;
    NeuralTrainer trainer(s, o);
    std::vector<BlockGradient> blocks;
    trainer.ComputeBlockGradients(0, trainer.blocks_per_step(), &blocks);
    std::vector<std::int32_t> scratch(s.texels, -1);
    const StepGradient g = ReduceInOrder(blocks, o.latent, scratch);
    for (const std::int32_t v : scratch) ASSERT_EQ(v, -1);

    const NeuralModel& m = trainer.model();
    NetD d(m.net.shape(), 0);
    for (Eigen::Index k = 0; k < d.parameter_count(); ++k) d.parameters()[k] = m.net.parameters()[k];
    std::vector<std::int64_t> batch;
    trainer.StepSamples(0, &batch);
    const int E = o.encoding.Width(), n = int(batch.size());
    Eigen::MatrixXd X(o.latent + E, n), T(3, n);
    for (int j = 0; j < n; ++j) {
      const std::int64_t i = batch[j];
      X.col(j).head(o.latent) = m.latents.col(s.texel[i]).cast<double>();
      float enc[64];
      EncodeDirections(o.encoding, &s.wi[3 * i], &s.wo[3 * i], enc);
      for (int e = 0; e < E; ++e) X(o.latent + e, j) = enc[e];
      for (int c = 0; c < 3; ++c) T(c, j) = s.target[3 * i + c];
    }
    NetD::Workspace ws;
    const Eigen::MatrixXd Y = d.Forward(X, ws);
    // The trainer evaluates e^y at min(y, max target + 1): the test's outputs stay below that.
    ASSERT_LT(Y.maxCoeff(), *std::max_element(s.target.begin(), s.target.end()) + 1);
    Eigen::MatrixXd dY;
    const double loss = TrainingLoss(Y, T, w, S, &dY);
    EXPECT_NEAR(g.loss, loss, 1e-5 * loss);
    EXPECT_EQ(g.values, 3 * n);
    std::vector<double> gd(d.parameter_count(), 0.0);
    Eigen::MatrixXd dX;
    d.Backward(X, dY, ws, gd.data(), &dX);
    double scale = 0;
    for (const double v : gd) scale = std::max(scale, std::abs(v));
    for (Eigen::Index k = 0; k < d.parameter_count(); ++k) ASSERT_NEAR(g.parameters[k], gd[k], 1e-4 * scale) << k;
    // Central differences of the double loss, every 5th parameter: O(h^2) = 1e-10 truncation.
    for (Eigen::Index k = 0; k < d.parameter_count(); k += 5) {
      const double p0 = d.parameters()[k], h = 1e-5;
      d.parameters()[k] = p0 + h;
      const double up = TrainingLoss(d.Forward(X, ws), T, w, S, nullptr);
      d.parameters()[k] = p0 - h;
      const double down = TrainingLoss(d.Forward(X, ws), T, w, S, nullptr);
      d.parameters()[k] = p0;
      ASSERT_NEAR((up - down) / (2 * h), gd[k], 1e-6 * scale + 1e-9) << k;
    }
    // Latents: each texel's gradient is the sum over its samples in the batch.
    Eigen::MatrixXd lat = Eigen::MatrixXd::Zero(o.latent, s.texels);
    for (int j = 0; j < n; ++j) lat.col(s.texel[batch[j]]) += dX.col(j).head(o.latent);
    ASSERT_EQ(g.texels.size(), 16u);  // 1024 samples of 16 texels: all appear
    const double lat_scale = lat.cwiseAbs().maxCoeff();
    for (std::size_t i = 0; i < g.texels.size(); ++i)
      for (int l = 0; l < o.latent; ++l)
        EXPECT_NEAR(g.latents[i * o.latent + l], lat(l, g.texels[i]), 1e-4 * lat_scale) << g.texels[i] << " " << l;
  }
}

TEST(NeuralTrainer, FitsSyntheticLobesOnHeldOutDirections) {
  // 64 texels x 256 (wi, wo) pairs; held out: another 256 pairs per texel. A constant leaves the
  // targets' spread (0.86 in log); the fit must leave under 0.08 on held-out directions.
  // Measured: 0.0501 (SiLU, half vector, 3000 steps of 1024, seed 5).
  const NeuralSamples train = test::LobeSamples(64, 256, 1), held = test::LobeSamples(64, 256, 2);
  NeuralTrainOptions o = SmallOptions();
  o.steps = 3000;
  o.encoding.half_vector = true;
  o.activation = Activation::kSilu;
  NeuralTrainSummary summary;
  const OneThread one;
  const NeuralModel m = TrainNeural(train, o, {}, &summary);
  const double spread = test::LobeSpread(train), rmse = test::LobeRmse(m, held);
  RecordProperty("held_out_rmse", fmt::format("{:.4f}", rmse));
  EXPECT_GT(spread, 0.8);
  EXPECT_LT(rmse, 0.08) << "spread " << spread;
  EXPECT_LT(summary.last_loss, 0.1 * summary.first_loss);
}

void ExpectSameModel(const NeuralModel& a, const NeuralModel& b, const std::string& what) {
  ASSERT_EQ(a.net.parameter_count(), b.net.parameter_count());
  EXPECT_EQ(0, std::memcmp(a.net.parameters().data(), b.net.parameters().data(), sizeof(float) * a.net.parameter_count()))
      << what;
  ASSERT_EQ(a.latents.size(), b.latents.size());
  EXPECT_EQ(0, std::memcmp(a.latents.data(), b.latents.data(), sizeof(float) * a.latents.size())) << what;
}

TEST(NeuralTrainer, SameBitsForOneAndTwoThreadsAndForBlocksComputedInParts) {
  const NeuralSamples s = test::LobeSamples(50, 61, 3);  // 3050 samples: epochs straddle batches
  NeuralTrainOptions o = SmallOptions();
  o.batch = 1000;  // 4 blocks, the last one 232 samples
  o.encoding.half_vector = true;
  o.encoding.fourier = 1;
  const int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  const NeuralModel one = TrainNeural(s, o);
  omp_set_num_threads(2);
  const NeuralModel two = TrainNeural(s, o);
  // Blocks computed in two calls (as two MPI ranks would: blocks 0-1 and 2-3), then reduced together.
  NeuralTrainer parts(s, o);
  for (std::int64_t k = 0; k < parts.steps(); ++k) {
    std::vector<BlockGradient> a, b;
    parts.ComputeBlockGradients(0, 2, &a);
    parts.ComputeBlockGradients(2, 2, &b);
    a.insert(a.end(), b.begin(), b.end());
    parts.ApplyStep(a);
  }
  omp_set_num_threads(saved);
  ExpectSameModel(one, two, "1 vs 2 threads");
  ExpectSameModel(one, parts.model(), "blocks in parts");
  // A different seed gives different numbers (the comparison above can fail).
  o.seed = 6;
  const NeuralModel other = TrainNeural(s, o);
  EXPECT_NE(0, std::memcmp(one.net.parameters().data(), other.net.parameters().data(), sizeof(float) * 8));
}

TEST(NeuralTrainer, EveryEpochVisitsEverySampleOnce) {
  const NeuralSamples s = test::LobeSamples(10, 30, 4);  // 300 samples, batch 128
  NeuralTrainOptions o = SmallOptions();
  o.batch = 128;
  o.block = 128;
  NeuralTrainer t(s, o);
  std::vector<int> seen(300, 0);
  std::vector<std::int64_t> batch;
  for (std::int64_t k = 0; k < 7; ++k) {  // 896 positions: epochs 0, 1 and part of 2
    t.StepSamples(k, &batch);
    for (int j = 0; j < 128; ++j)
      if (k * 128 + j < 600) ++seen[batch[j]];
  }
  for (const int c : seen) EXPECT_EQ(c, 2);
}

TEST(NeuralTrainer, CallbackCancels) {
  const NeuralSamples s = test::LobeSamples(8, 64, 1);
  int calls = 0;
  const NeuralProgress stop = [&](std::int64_t step, std::int64_t total, double loss) {
    EXPECT_EQ(step, calls + 1);
    EXPECT_EQ(total, 20);
    EXPECT_TRUE(std::isfinite(loss));
    return ++calls < 3;
  };
  NeuralTrainOptions o = SmallOptions();
  o.batch = 256;
  EXPECT_THROW(TrainNeural(s, o, stop), Cancelled);
  EXPECT_EQ(calls, 3);
}

ExitCode CodeOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.code();
  }
  return ExitCode::kOk;
}

TEST(NeuralTrainer, RefusesNonFiniteTargetsBadSamplesAndBadOptions) {
  const NeuralSamples good = test::LobeSamples(4, 16, 1);
  const auto train = [](const NeuralSamples& s, const NeuralTrainOptions& o) { TrainNeural(s, o); };
  NeuralTrainOptions o = SmallOptions();
  o.batch = 32;
  o.block = 16;
  for (const float bad : {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    NeuralSamples s = good;
    s.target[17] = bad;
    EXPECT_EQ(CodeOf([&] { train(s, o); }), ExitCode::kBadInput) << bad;
    s = good;
    s.wo[5] = bad;
    EXPECT_EQ(CodeOf([&] { train(s, o); }), ExitCode::kBadInput) << bad;
  }
  NeuralSamples s = good;
  s.texel[3] = 4;  // of 4 texels
  EXPECT_EQ(CodeOf([&] { train(s, o); }), ExitCode::kBadInput);
  s = good;
  s.target.pop_back();
  EXPECT_EQ(CodeOf([&] { train(s, o); }), ExitCode::kBadInput);
  s = good;
  s.wi[0] = 2;  // not a unit vector
  EXPECT_EQ(CodeOf([&] { train(s, o); }), ExitCode::kBadInput);
  NeuralTrainOptions bad = o;
  bad.block = 64;  // > batch
  EXPECT_EQ(CodeOf([&] { train(good, bad); }), ExitCode::kUsage);
  bad = o;
  bad.learning_rate = 0;
  EXPECT_EQ(CodeOf([&] { train(good, bad); }), ExitCode::kUsage);
  bad = o;
  bad.encoding.fourier = 9;
  EXPECT_EQ(CodeOf([&] { train(good, bad); }), ExitCode::kUsage);
  bad = o;
  bad.linear_loss = 1.5;
  EXPECT_EQ(CodeOf([&] { train(good, bad); }), ExitCode::kUsage);
  EXPECT_EQ(CodeOf([&] { train(good, o); }), ExitCode::kOk);
}

TEST(NeuralTrainer, GrazingDirectionsGiveFiniteResults) {
  // Directions in the tangent plane (z = 0) and opposite pairs (wi = -wo: no half vector),
  // targets of log(1e-3) and log(1e4), every encoding feature and activation, log and linear loss.
  NeuralSamples s;
  s.texels = 4;
  for (int i = 0; i < 256; ++i) {
    const double phi = 0.1 * i;
    const float w[3] = {float(std::cos(phi)), float(std::sin(phi)), 0.f};
    s.texel.push_back(i % 4);
    s.wi.insert(s.wi.end(), w, w + 3);
    if (i % 2) s.wo.insert(s.wo.end(), {-w[0], -w[1], 0.f});
    else s.wo.insert(s.wo.end(), {0.f, 0.f, 1.f});
    for (int c = 0; c < 3; ++c) s.target.push_back(float(i % 3 ? std::log(1e-3) : std::log(1e4)));
  }
  const OneThread one;
  for (const double w : {0.0, 1.0})
  for (const Activation act : kActivations) {
    SCOPED_TRACE(fmt::format("linear_loss {}", w));
    NeuralTrainOptions o = SmallOptions();
    o.batch = 128;
    o.block = 64;
    o.steps = 50;
    o.linear_loss = w;
    o.activation = act;
    o.encoding.half_vector = true;
    o.encoding.fourier = 3;
    NeuralTrainSummary summary;
    const NeuralModel m = TrainNeural(s, o, {}, &summary);
    EXPECT_TRUE(std::isfinite(summary.last_loss)) << ActivationName(act);
    for (const float v : m.net.parameters()) ASSERT_TRUE(std::isfinite(v)) << ActivationName(act);
    EXPECT_TRUE(m.latents.allFinite()) << ActivationName(act);
    Eigen::MatrixXf out;
    m.Evaluate(s.texel.data(), s.wi.data(), s.wo.data(), s.size(), &out);
    EXPECT_TRUE(out.allFinite()) << ActivationName(act);
  }
}

}  // namespace
}  // namespace btf
