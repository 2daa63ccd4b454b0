// The constraint terms of the constrained space (see space_impl.hpp) evaluated: F, J and G stacked from the terms'
// rows (the built-in terms' own in builtin_terms.cpp), compiled expressions, Python callbacks in batches, the
// floating base's chain rule, the per-state check of validity and path checks (state_check), and the projection.
#include "space_impl.hpp"

#include <pinocchio/algorithm/center-of-mass.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/kinematics.hpp>

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>

namespace mgcore {

// A compiled expression's rows at q (forward kinematics done; with J, the joint Jacobians too): its frames'
// placements (and Jacobians, mapped to the active coordinates as put_row does) and the centre of mass when it
// reads it, then its program. J: its first row's start, n per row (null: values only).
void Space::Impl::expression_rows(Compiled& c, const double* q, double* F, double* J) {
  Leaves& leaves = c.leaves;
  leaves.q = q;
  const std::vector<int>& frames = c.expression.frames();
  const int nn = n();
  for (std::size_t s = 0; s < frames.size(); ++s) {
    const pinocchio::FrameIndex f = static_cast<pinocchio::FrameIndex>(frames[s]);
    const pinocchio::SE3& A = pinocchio::updateFramePlacement(model, data, f);
    leaves.position[s] = A.translation();
    leaves.rotation[s] = A.rotation();
    if (!J) continue;
    Ja.setZero();
    pinocchio::getFrameJacobian(model, data, f, pinocchio::LOCAL_WORLD_ALIGNED, Ja);
    for (int r = 0; r < 6; ++r) put_row(leaves.jacobian[s].data() + static_cast<long>(r) * nn, Ja.row(r));
  }
  if (c.expression.uses_com()) {
    if (J) {
      pinocchio::jacobianCenterOfMass(model, data, false);
      for (int r = 0; r < 3; ++r) put_row(leaves.com_jacobian.data() + static_cast<long>(r) * nn, data.Jcom.row(r));
    } else {
      pinocchio::centerOfMass(model, data, pinocchio::POSITION, false);
    }
    leaves.com = data.com[0];
  }
  c.expression.evaluate(leaves, F, J);
}

void ExpressionTerm::values(Space::Impl& p, const double* q, double* F) const {
  p.expression_rows(compiled, q, F, nullptr);
}

void ExpressionTerm::jacobian(Space::Impl& p, const double* q, double* F, double* J) const {
  p.expression_rows(compiled, q, F, J);
}

void ExpressionInequality::values(Space::Impl& p, const double* q, double* G) const {
  p.expression_rows(compiled, q, G, nullptr);
}

// Residual rows of every term from data's joint placements (forward kinematics done).
void Space::Impl::fill_residual(const double* q, double* F) {
  int row = 0;
  for (const auto& t : terms) {
    t->values(*this, q, F + row);
    row += t->rows();
  }
}

// J (m, n) row-major from the frame Jacobians (computeJointJacobians done).
void Space::Impl::fill_jacobian(const double* q, double* F, double* J) {
  const int nn = n();
  if (floating) map_base(q);
  int row = 0;
  for (const auto& t : terms) {
    t->jacobian(*this, q, F + row, J + static_cast<long>(row) * nn);
    row += t->rows();
  }
}

// base_map: the free flyer's v (linear and angular velocity in the base frame) per unit change of
// (x, y, z, yaw, pitch, roll): v_lin = R^T dp, omega = R^T E dtheta, E's columns the world axes of
// yaw (z), pitch (Rz y) and roll (Rz Ry x). (set_base, which puts the six base coordinates into pinocchio's q,
// is in space_impl.hpp.)
void Space::Impl::map_base(const double* q) {
  const Eigen::Matrix3d Rz = zyx(q[3], 0.0, 0.0), Rzy = zyx(q[3], q[4], 0.0), R = zyx(q[3], q[4], q[5]);
  Eigen::Matrix3d E;
  E.col(0) = Eigen::Vector3d::UnitZ();
  E.col(1) = Rz.col(1);
  E.col(2) = Rzy.col(0);
  base_map.setZero();
  base_map.topLeftCorner<3, 3>() = R.transpose();
  base_map.bottomRightCorner<3, 3>() = R.transpose() * E;
}

// G (g,) at q: forward kinematics, and pinocchio's centre of mass when an inequality reads it.
void Space::Impl::fill_inequality(const double* q, double* G) {
  if (com_needed) pinocchio::centerOfMass(model, data, to_full(q), false);
  else pinocchio::forwardKinematics(model, data, to_full(q));
  inequality_rows(q, G);
}

// G (g,) at q from data's kinematics (and centre of mass when an inequality reads it).
void Space::Impl::inequality_rows(const double* q, double* G) {
  int row = 0;
  for (const auto& c : inequalities) {
    c->values(*this, q, G + row);
    row += c->rows();
  }
}

// One state's equality violation (max |F_i| / tol_i; 0 without terms) and, when it is within limit, whether the
// built-in inequalities hold, from one forward kinematics (the centre of mass's pass when the polygon needs it;
// pinocchio's centerOfMass runs forwardKinematics first, so the residual is the same) where Space::violation and
// inequalities_hold make one each. Built-in terms only (not batched()); counts the evaluation as residual does.
double Space::Impl::state_check(const double* q, double limit, bool& hold) {
  hold = true;
  if (m == 0 && g == 0) return 0.0;
  if (com_needed) pinocchio::centerOfMass(model, data, to_full(q), false);
  else pinocchio::forwardKinematics(model, data, to_full(q));
  double worst = 0.0;
  if (m > 0) {
    ++tally->evaluations;
    state_F.resize(m);
    fill_residual(q, state_F.data());
    for (int i = 0; i < m; ++i) worst = std::max(worst, std::abs(state_F[i]) / tolerance[i]);
  }
  if (worst <= limit && g > 0) {
    state_G.resize(g);
    inequality_rows(q, state_G.data());
    for (double x : state_G)
      if (x > 0) hold = false;
  }
  return worst;
}

void Space::inequality(const double* q, double* G) {
  if (impl_->g) impl_->fill_inequality(q, G);
}

bool Space::inequalities_hold(const double* q) {
  const int gg = impl_->g;
  if (!gg) return true;
  double G[64];
  std::vector<double> big;
  double* out = G;
  if (gg > 64) {
    big.resize(gg);
    out = big.data();
  }
  impl_->fill_inequality(q, out);
  for (int i = 0; i < gg; ++i)
    if (out[i] > 0) return false;
  return true;
}

void Space::residual(const double* q, double* F) { residuals(q, 1, F); }

void Space::jacobian(const double* q, double* F, double* J) { jacobians(q, 1, F, J); }

double Space::violation(const double* q) {
  const Impl& p = *impl_;
  if (p.m == 0) return 0.0;
  double F[64];
  std::vector<double> big;
  double* f = F;
  if (p.m > 64) {
    big.resize(p.m);
    f = big.data();
  }
  residual(q, f);
  double worst = 0.0;
  for (int i = 0; i < p.m; ++i) worst = std::max(worst, std::abs(f[i]) / p.tolerance[i]);
  return worst;
}

Projection Space::project(double* q, double tol, int max_iters, double damping, double max_step) {
  Projection out;
  project_many(q, 1, tol, max_iters, damping, max_step, &out);
  return out;
}

// ------------------------------------------------------------------ Python callbacks and batches
// The callback terms' rows of F (B, m) and, when J is not null, of J (B, m, n) at q (B, n).
void Space::Impl::fill_callbacks(const double* q, long B, Counters& counts, double* F, double* J) {
  const int nn = n(), mm = m;
  int offset = 0;
  std::vector<double> Fc, Jc;
  for (const auto& t : terms) {
    const int rows = t->rows(), index = t->callback();
    if (index >= 0 && B > 0 && rows > 0) {
      Fc.assign(B * rows, 0.0);
      if (J) Jc.assign(B * rows * nn, 0.0);
      ++counts.callback_calls;
      counts.callback_rows += B;
      callbacks[index](q, B, Fc.data(), J ? Jc.data() : nullptr);
      for (long b = 0; b < B; ++b)  // rows [offset, offset + rows) of each configuration's F and J
        for (int r = 0; r < rows; ++r) {
          F[b * mm + offset + r] = Fc[b * rows + r];
          if (J) std::copy_n(Jc.data() + (b * rows + r) * nn, nn, J + (b * mm + offset + r) * nn);
        }
    }
    offset += rows;
  }
}

void Space::residuals(const double* q, long B, double* F) {
  Impl& p = *impl_;
  const int nn = n(), mm = m();
  counts.evaluations += B;
  if (p.native_terms)
    for (long b = 0; b < B; ++b) {
      pinocchio::forwardKinematics(p.model, p.data, p.to_full(q + b * nn));
      p.fill_residual(q + b * nn, F + b * mm);
    }
  p.fill_callbacks(q, B, counts, F, nullptr);
}

void Space::jacobians(const double* q, long B, double* F, double* J) {
  Impl& p = *impl_;
  const int nn = n(), mm = m();
  counts.jacobians += B;
  if (p.native_terms)
    for (long b = 0; b < B; ++b) {
      pinocchio::computeJointJacobians(p.model, p.data, p.to_full(q + b * nn));
      p.fill_jacobian(q + b * nn, F + b * mm, J + b * mm * nn);
    }
  p.fill_callbacks(q, B, counts, F, J);
}

void Space::violations(const double* q, long B, double* v) {
  const Impl& p = *impl_;
  const int mm = m();
  if (mm == 0) {
    std::fill(v, v + B, 0.0);
    return;
  }
  std::vector<double> F(B * mm);
  residuals(q, B, F.data());
  for (long b = 0; b < B; ++b) {
    double worst = 0.0;
    for (int i = 0; i < mm; ++i) worst = std::max(worst, std::abs(F[b * mm + i]) / p.tolerance[i]);
    v[b] = worst;
  }
}

void Space::inequalities(const double* q, long B, double* G) {
  Impl& p = *impl_;
  if (!p.p || B == 0) return;
  ++counts.callback_calls;
  counts.callback_rows += B;
  p.inequality(q, B, G);
}

void Space::project_many(double* q, long B, double tol, int max_iters, double damping, double max_step,
                         Projection* out) {
  const Impl& p = *impl_;
  const int nn = n(), mm = m();
  std::vector<long> active;
  for (long b = 0; b < B; ++b) {
    Eigen::Map<Vec> x(q + b * nn, nn);
    x = x.cwiseMax(p.lower).cwiseMin(p.upper);
    out[b] = Projection{false, max_iters, INFINITY};
    active.push_back(b);
  }
  RowMat X, F, J;
  Vec Fr(mm), dq(nn);
  RowMat Jr(mm, nn), Jb(mm, nn);
  Eigen::MatrixXd A(mm, mm);
  auto step = [&](const RowMat& Jm, double lam) {
    A.noalias() = Jm * Jm.transpose();
    A.diagonal().array() += lam;
    dq.noalias() = -Jm.transpose() * A.ldlt().solve(Fr);
  };
  for (int it = 0; it <= max_iters && !active.empty(); ++it) {
    const long a = static_cast<long>(active.size());
    X.resize(a, nn);
    for (long r = 0; r < a; ++r) X.row(r) = Eigen::Map<const Eigen::RowVectorXd>(q + active[r] * nn, nn);
    F.resize(a, mm);
    J.resize(a * mm, nn);
    if (mm) jacobians(X.data(), a, F.data(), J.data());
    else counts.jacobians += a;
    std::vector<long> still;
    for (long r = 0; r < a; ++r) {
      const long b = active[r];
      const double err = mm ? F.row(r).cwiseAbs().maxCoeff() : 0.0;
      out[b].residual = err;
      if (err <= tol) {
        out[b].converged = true;
        out[b].iterations = it;
        continue;
      }
      if (it == max_iters) continue;
      ++counts.projection_steps;
      Eigen::Map<Vec> x(q + b * nn, nn);
      Fr = F.row(r).transpose();
      Jr = J.middleRows(r * mm, mm);
      const double lam = Fr.squaredNorm() + damping;
      step(Jr, lam);
      bool blocked = false;
      Jb = Jr;
      for (int i = 0; i < nn; ++i)
        if ((x[i] <= p.lower[i] + 1e-9 && dq[i] < 0) || (x[i] >= p.upper[i] - 1e-9 && dq[i] > 0)) {
          Jb.col(i).setZero();
          blocked = true;
        }
      if (blocked) step(Jb, lam);
      const double norm = dq.norm();
      dq *= std::min(1.0, max_step / std::max(norm, 1e-12));
      x = (x + dq).cwiseMax(p.lower).cwiseMin(p.upper);
      still.push_back(b);
    }
    active.swap(still);
  }
}

}  // namespace mgcore
