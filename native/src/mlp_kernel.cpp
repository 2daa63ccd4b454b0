// The decoder's matrix products (core.hpp, Decoder), built as their own shared library with the building
// machine's vector instructions (native/CMakeLists.txt): Eigen compiled for another instruction set must not
// share a library with the module's Eigen (their inline functions, the aligned allocator among them, would be
// merged). Only raw float arrays cross this boundary; every Eigen object here is made and freed here.
#include <Eigen/Core>

namespace {
using MatF = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using MapF = Eigen::Map<const MatF>;
}  // namespace

// out (B, widths[layers]) = the network on x (B, widths[0]): x W_i^T + b_i per layer, weights[i] (widths[i + 1],
// widths[i]) and biases[i] (widths[i + 1],) row-major, SiLU after every layer but the last.
extern "C" __attribute__((visibility("default"))) void mg_mlp_forward(int layers, const int* widths,
                                                                      const float* const* weights,
                                                                      const float* const* biases, long B,
                                                                      const float* x, float* out) {
  MatF a = MapF(x, B, widths[0]), h;
  for (int i = 0; i < layers; ++i) {
    h.resize(B, widths[i + 1]);
    h.noalias() = a * MapF(weights[i], widths[i + 1], widths[i]).transpose();
    h.rowwise() += Eigen::Map<const Eigen::RowVectorXf>(biases[i], widths[i + 1]);
    if (i + 1 < layers) h = h.array() / (1.0f + (-h.array()).exp());  // SiLU
    a.swap(h);
  }
  Eigen::Map<MatF>(out, B, widths[layers]) = a;
}
