// The sampling network of a learned sampler in the core (core.hpp, Decoder): a decode is a few small
// matrix products (mlp_kernel.cpp), where torch spends most of a 64-row call in dispatch and allocation.
#include <cmath>
#include <stdexcept>
#include <string>

#include "core.hpp"

extern "C" void mg_mlp_forward(int layers, const int* widths, const float* const* weights, const float* const* biases,
                               long B, const float* x, float* out);  // mlp_kernel.cpp

namespace mgcore {

namespace {

// xoshiro256** (Blackman and Vigna), its state filled by splitmix64 from one seed: the same rows on every platform.
class Random {
 public:
  explicit Random(std::uint64_t seed) {
    for (auto& word : s_) {
      seed += 0x9E3779B97F4A7C15ULL;
      std::uint64_t z = seed;
      z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
      z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
      word = z ^ (z >> 31);
    }
  }
  std::uint64_t next() {
    const std::uint64_t result = rotl(s_[1] * 5, 7) * 9, t = s_[1] << 17;
    s_[2] ^= s_[0], s_[3] ^= s_[1], s_[1] ^= s_[2], s_[0] ^= s_[3], s_[2] ^= t, s_[3] = rotl(s_[3], 45);
    return result;
  }
  double open01() { return (static_cast<double>(next() >> 11) + 0.5) * 0x1.0p-53; }  // in (0, 1)

 private:
  static std::uint64_t rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
  std::uint64_t s_[4];
};

void require(bool ok, const std::string& message) {
  if (!ok) throw std::invalid_argument("decoder: " + message);
}

// Checks that net's layers chain from `inputs` inputs to `outputs` outputs, naming it in the message.
void check_net(const Decoder::Net& net, long inputs, long outputs, const std::string& name) {
  require(!net.weights.empty() && net.weights.size() == net.biases.size(),
          "give the " + name + " one bias per weight matrix, at least one layer");
  long width = inputs;
  for (std::size_t i = 0; i < net.weights.size(); ++i) {
    require(net.weights[i].cols() == width && net.biases[i].size() == net.weights[i].rows(),
            name + " layer " + std::to_string(i) + " takes " + std::to_string(net.weights[i].cols()) +
                " inputs, the layer before gives " + std::to_string(width));
    width = net.weights[i].rows();
  }
  require(width == outputs, "the " + name + "'s last layer gives " + std::to_string(width) + " outputs for " +
                                std::to_string(outputs));
}

// x (B, m) carried from t = 0 to 1 by dx/dt = velocity([x, yn, t]) as models/base.py integrate does: steps - 1
// Heun steps, then one Euler step.
Decoder::MatF integrate(const Decoder::Net& velocity, Decoder::MatF x, const Eigen::RowVectorXf& yn, int steps) {
  const long B = x.rows(), m = x.cols(), k = yn.size();
  const float h = 1.0f / static_cast<float>(steps);
  Decoder::MatF in(B, m + k + 1);
  in.middleCols(m, k) = yn.replicate(B, 1);
  for (int i = 0; i + 1 < steps; ++i) {
    in.leftCols(m) = x;
    in.col(m + k).setConstant(static_cast<float>(i) * h);
    const Decoder::MatF v = velocity.forward(in);
    in.leftCols(m) = x + h * v;
    in.col(m + k).setConstant(static_cast<float>(i + 1) * h);
    x += (0.5f * h) * (v + velocity.forward(in));
  }
  in.leftCols(m) = x;
  in.col(m + k).setConstant(1.0f - h);
  x += h * velocity.forward(in);
  return x;
}

}  // namespace

Decoder::Decoder(std::vector<MatF> weights, std::vector<VecF> biases, int latent, bool uniform, const Vec& q_mean,
                 const Vec& q_std, const Vec& y_mean, const Vec& y_std, const Vec& lower, const Vec& upper, int steps,
                 std::vector<MatF> prior_weights, std::vector<VecF> prior_biases, int prior_steps)
    : net_{std::move(weights), std::move(biases)}, prior_{std::move(prior_weights), std::move(prior_biases)},
      latent_(latent), uniform_(uniform), steps_(steps), prior_steps_(prior_steps), q_mean_(q_mean.cast<float>()),
      q_std_(q_std.cast<float>()), y_mean_(y_mean.cast<float>()), y_std_(y_std.cast<float>()), lower_(lower),
      upper_(upper) {
  require(latent > 0, "the latent size must be positive");
  require(y_std.size() == y_mean.size() && q_std.size() == q_mean.size() && lower.size() == q_mean.size() &&
              upper.size() == q_mean.size(),
          "normalisation vectors and limits must match the condition and configuration sizes");
  require(steps >= 0 && prior_steps >= 0, "the number of integration steps must be >= 0");
  require(steps == 0 || latent == q_mean.size(), "a velocity field's latent size is the number of joints");
  const long k = y_mean.size();
  check_net(net_, latent + k + (steps > 0 ? 1 : 0), q_mean.size(), "network");
  if (prior_steps > 0) check_net(prior_, latent + k + 1, latent, "prior");
  require(prior_steps > 0 || prior_.weights.empty(), "prior layers need prior_steps > 0");
}

Decoder::MatF Decoder::latent_rows(long count, std::uint64_t seed) const {
  require(count >= 0, "the number of rows must be >= 0");
  MatF z(count, latent_);
  Random random(seed);
  float* out = z.data();
  const long size = z.size();
  if (uniform_) {
    for (long i = 0; i < size; ++i) out[i] = static_cast<float>(2.0 * random.open01() - 1.0);
    return z;
  }
  for (long i = 0; i < size; i += 2) {  // Box-Muller: two normals from two uniforms
    const double radius = std::sqrt(-2.0 * std::log(random.open01())), angle = 2.0 * M_PI * random.open01();
    out[i] = static_cast<float>(radius * std::cos(angle));
    if (i + 1 < size) out[i + 1] = static_cast<float>(radius * std::sin(angle));
  }
  return z;
}

Decoder::MatF Decoder::Net::forward(const MatF& x) const {
  std::vector<int> widths{static_cast<int>(x.cols())};
  std::vector<const float*> w, b;
  for (std::size_t i = 0; i < weights.size(); ++i) {
    widths.push_back(static_cast<int>(weights[i].rows()));
    w.push_back(weights[i].data());
    b.push_back(biases[i].data());
  }
  MatF out(x.rows(), widths.back());
  mg_mlp_forward(static_cast<int>(weights.size()), widths.data(), w.data(), b.data(), x.rows(), x.data(), out.data());
  return out;
}

RowMat Decoder::decode(const MatF& z, const Vec& y) const {
  require(z.cols() == latent_, "latent rows must have " + std::to_string(latent_) + " columns");
  require(y.size() == y_mean_.size(), "the condition must have " + std::to_string(y_mean_.size()) + " values");
  const long B = z.rows(), k = y_mean_.size();
  const Eigen::RowVectorXf yn = ((y.cast<float>() - y_mean_).array() / y_std_.array()).matrix().transpose();
  const MatF latent = prior_steps_ > 0 ? integrate(prior_, z, yn, prior_steps_) : z;
  MatF x;
  if (steps_ == 0) {
    MatF in(B, latent_ + k);
    in.leftCols(latent_) = latent;
    in.rightCols(k) = yn.replicate(B, 1);
    x = net_.forward(in);
  } else {  // a velocity field: dx/dt = v([x, y, t]) from the latent rows, as models/cfm.py samples
    x = integrate(net_, latent, yn, steps_);
  }
  const Eigen::RowVectorXf mean = q_mean_.transpose(), std = q_std_.transpose();
  x = (x.array().rowwise() * std.array()).rowwise() + mean.array();
  RowMat q = x.cast<double>();
  for (long r = 0; r < B; ++r) q.row(r) = q.row(r).cwiseMax(lower_.transpose()).cwiseMin(upper_.transpose());
  return q;
}

}  // namespace mgcore
