// Compiled expressions (see core.hpp): a traced user residual run per configuration, values and forward-mode
// gradients over the active coordinates. The space (terms.cpp) fills the leaves from pinocchio.
#include "core.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace mgcore {

namespace {

bool is_leaf(Op op) { return op == Op::Q || op == Op::CONST || op == Op::POS || op == Op::ROT || op == Op::COM; }
bool is_binary(Op op) { return op >= Op::ADD && op <= Op::MIN; }
bool is_unary(Op op) { return op >= Op::NEG && op <= Op::TANH; }

}  // namespace

Expression::Expression(std::vector<Instruction> code, std::vector<double> constants, std::vector<int> frames,
                       std::vector<int> outputs, int n)
    : code_(std::move(code)), constants_(std::move(constants)), frames_(std::move(frames)), outputs_(std::move(outputs)),
      n_(n) {
  const int N = static_cast<int>(code_.size());
  varies_.assign(N, 0);
  for (int i = 0; i < N; ++i) {
    const Instruction& c = code_[i];
    const std::string where = "expression instruction " + std::to_string(i) + ": ";
    auto operand = [&](int r) {
      if (r < 0 || r >= i) throw std::invalid_argument(where + "operand " + std::to_string(r) + " is not an earlier register");
    };
    auto within = [&](int x, int size, const char* what) {
      if (x < 0 || x >= size) throw std::invalid_argument(where + what + " " + std::to_string(x) + " out of range");
    };
    switch (c.op) {
      case Op::Q:
        within(c.a, n_, "coordinate");
        varies_[i] = 1;
        break;
      case Op::CONST:
        within(c.a, static_cast<int>(constants_.size()), "constant");
        break;
      case Op::POS:
        within(c.a, static_cast<int>(frames_.size()), "frame slot");
        within(c.b, 3, "axis");
        varies_[i] = 1;
        break;
      case Op::ROT:
        within(c.a, static_cast<int>(frames_.size()), "frame slot");
        within(c.b, 9, "rotation entry");
        varies_[i] = 1;
        break;
      case Op::COM:
        within(c.b, 3, "axis");
        uses_com_ = true;
        varies_[i] = 1;
        break;
      default:
        if (is_unary(c.op)) {
          operand(c.a);
          varies_[i] = varies_[c.a];
        } else if (is_binary(c.op)) {
          operand(c.a);
          operand(c.b);
          varies_[i] = varies_[c.a] || varies_[c.b];
        } else {
          throw std::invalid_argument(where + "unknown operation " + std::to_string(static_cast<int>(c.op)));
        }
    }
  }
  for (int r : outputs_)
    if (r < 0 || r >= N) throw std::invalid_argument("expression output " + std::to_string(r) + " is not a register");
  for (int f : frames_)
    if (f < 0) throw std::invalid_argument("expression frame id " + std::to_string(f) + " out of range");
  value_.assign(N, 0.0);
  gradient_.assign(static_cast<std::size_t>(N) * n_, 0.0);
}

Leaves Expression::leaves() const {
  Leaves l;
  const std::size_t F = frames_.size();
  l.position.assign(F, Eigen::Vector3d::Zero());
  l.rotation.assign(F, Eigen::Matrix3d::Identity());
  l.jacobian.assign(F, RowMat::Zero(6, n_));
  l.com_jacobian = RowMat::Zero(3, n_);
  return l;
}

void Expression::evaluate(const Leaves& leaves, double* F, double* J) {
  const int N = static_cast<int>(code_.size()), n = n_;
  const bool derive = J != nullptr;
  double* v = value_.data();
  for (int i = 0; i < N; ++i) {
    const Instruction& c = code_[i];
    const double x = is_leaf(c.op) ? 0.0 : v[c.a];
    const double y = is_binary(c.op) ? v[c.b] : 0.0;
    // the value, and the gradient as da * ga + db * gb (ga, gb: the operands' gradients)
    double out = 0.0, da = 0.0, db = 0.0;
    double* g = gradient_.data() + static_cast<std::size_t>(i) * n;
    switch (c.op) {
      case Op::Q:
        out = leaves.q[c.a];
        if (derive) {
          std::fill(g, g + n, 0.0);
          g[c.a] = 1.0;
        }
        break;
      case Op::CONST:
        out = constants_[c.a];
        if (derive) std::fill(g, g + n, 0.0);
        break;
      case Op::POS:
        out = leaves.position[c.a][c.b];
        if (derive) std::copy_n(leaves.jacobian[c.a].row(c.b).data(), n, g);
        break;
      case Op::ROT: {
        // d R(:, j) = omega x R(:, j): row i is omega_{i+1} R(i+2, j) - omega_{i+2} R(i+1, j)
        const int r = c.b / 3, col = c.b % 3, r1 = (r + 1) % 3, r2 = (r + 2) % 3;
        const Eigen::Matrix3d& R = leaves.rotation[c.a];
        out = R(r, col);
        if (derive) {
          const RowMat& Jf = leaves.jacobian[c.a];
          const double u = R(r2, col), w = R(r1, col);
          for (int k = 0; k < n; ++k) g[k] = Jf(3 + r1, k) * u - Jf(3 + r2, k) * w;
        }
        break;
      }
      case Op::COM:
        out = leaves.com[c.b];
        if (derive) std::copy_n(leaves.com_jacobian.row(c.b).data(), n, g);
        break;
      case Op::NEG: out = -x, da = -1.0; break;
      case Op::SQRT: out = std::sqrt(x), da = 0.5 / out; break;
      case Op::SIN: out = std::sin(x), da = std::cos(x); break;
      case Op::COS: out = std::cos(x), da = -std::sin(x); break;
      case Op::TAN: out = std::tan(x), da = 1.0 + out * out; break;
      case Op::ASIN: out = std::asin(x), da = 1.0 / std::sqrt(1.0 - x * x); break;
      case Op::ACOS: out = std::acos(x), da = -1.0 / std::sqrt(1.0 - x * x); break;
      case Op::ATAN: out = std::atan(x), da = 1.0 / (1.0 + x * x); break;
      case Op::EXP: out = std::exp(x), da = out; break;
      case Op::LOG: out = std::log(x), da = 1.0 / x; break;
      case Op::ABS: out = std::abs(x), da = x > 0 ? 1.0 : x < 0 ? -1.0 : 0.0; break;
      case Op::TANH: out = std::tanh(x), da = 1.0 - out * out; break;
      case Op::ADD: out = x + y, da = 1.0, db = 1.0; break;
      case Op::SUB: out = x - y, da = 1.0, db = -1.0; break;
      case Op::MUL: out = x * y, da = y, db = x; break;
      case Op::DIV: out = x / y, da = 1.0 / y, db = -out / y; break;
      case Op::POW:
        out = std::pow(x, y);
        da = y * std::pow(x, y - 1.0);
        db = varies_[c.b] ? out * std::log(x) : 0.0;  // a constant exponent: no log of a negative base
        break;
      case Op::ATAN2: {
        const double s = x * x + y * y;
        out = std::atan2(x, y), da = y / s, db = -x / s;
        break;
      }
      case Op::MAX:  // numpy's maximum and minimum: NaN when either is NaN
      case Op::MIN: {
        const bool first = std::isnan(x) || (!std::isnan(y) && (c.op == Op::MAX ? x >= y : x <= y));
        out = first ? x : y, da = first ? 1.0 : 0.0, db = 1.0 - da;
        break;
      }
    }
    v[i] = out;
    if (!derive || is_leaf(c.op)) continue;
    if (!varies_[i]) {
      std::fill(g, g + n, 0.0);
      continue;
    }
    const double* ga = gradient_.data() + static_cast<std::size_t>(c.a) * n;
    const bool second = is_binary(c.op) && varies_[c.b] && db != 0.0;
    if (!varies_[c.a] || da == 0.0) {
      std::fill(g, g + n, 0.0);
    } else {
      for (int k = 0; k < n; ++k) g[k] = da * ga[k];
    }
    if (second) {
      const double* gb = gradient_.data() + static_cast<std::size_t>(c.b) * n;
      for (int k = 0; k < n; ++k) g[k] += db * gb[k];
    }
  }
  const int m = rows();
  for (int r = 0; r < m; ++r) {
    F[r] = v[outputs_[r]];
    if (derive) std::copy_n(gradient_.data() + static_cast<std::size_t>(outputs_[r]) * n, n, J + static_cast<std::size_t>(r) * n);
  }
}

}  // namespace mgcore
