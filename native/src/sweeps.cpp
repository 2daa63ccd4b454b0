// The dense path check of the constrained space (see space_impl.hpp): validate_path and its two shortcuts, certified
// constraints (a state whose rows rate bounds certify is not evaluated) and certified sweeps (spans of states cleared
// of collision at once; the bound and its proof are here), both giving the state-by-state report.
#include "space_impl.hpp"

#include <pinocchio/algorithm/center-of-mass.hpp>
#include <pinocchio/algorithm/geometry.hpp>
#include <pinocchio/algorithm/kinematics.hpp>

#include <coal/collision.h>
#include <pinocchio/collision/coal-pinocchio-conversions.hpp>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace mgcore {

// ---------------------------------------------------------------- Certified constraints
// validate_path(certify): a state is passed without evaluating it when rates bound how far each equality row and
// built-in inequality can have moved since the latest evaluated state e, and that is within its slack there.
// Every row r has a rate vector (n,) valid in every configuration: |F_r(q') - F_r(q)| <= rates_r . d, with d the
// coordinates' variation between q and q' along the path (Space::Impl::variation); the slack is tol_r - |F_r(e)|
// for an equality, -G_r(e) for an inequality. The rates are the sweeps' (Impl::rate_bound): a point fixed in joint
// j's frame moves at most lever_k per unit of a rotating coordinate k (lever_k: |the point| + the joints' steps
// between k and j) and 1 per unit of a sliding one (the base's x, y, z too); its frame turns at most 1 per unit of a
// rotating one (the base's yaw, pitch, roll too). Rows: a pose's positions and a sphere's distance: the point's
// rates; a pose's log3 rotation error: LOG_RATE times the turning rates while the error's angle stays <= 1 rad
// (|d log3| <= (a/2)/sin(a/2) |omega| at angle a), held by one more row per pose (rate: turning, slack: 1 - a(e));
// an orientation's rows basis_r . (R axis): |basis_r| |axis| times the turning rates; a linear row: |A_r|; the CoM
// polygon's rows: |normal_h| times the centre of mass's rates (the mass-weighted rates of the joints' inertia
// centres); a hemisphere's: |direction| |axis| times the turning rates. A closed chain, a Python callback or Python
// inequalities: no certificate (every state evaluated); nor a joint that is neither revolute, prismatic nor the base.
// (Each term's rows and guards: its rates() in builtin_terms.cpp; LOG_RATE and the rates' members: space_impl.hpp.)

// (n,) the speed bound of a point at c in joint j's frame (turning: of the frame's rotation) per unit speed of
// each coordinate, over every configuration.
Vec Space::Impl::point_rates(int j, const Eigen::Vector3d& c, bool turning) const {
  Vec r = Vec::Zero(n());
  const auto& supports = model.supports[j];
  double lever = c.norm();  // from the current joint's origin to the point, at most
  for (int depth = static_cast<int>(supports.size()) - 1; depth >= 1; --depth) {
    const int l = static_cast<int>(supports[depth]), k = coord_of[l];
    if (k == 0 && floating) {
      for (int a = 0; a < 3; ++a) r[a] = turning ? 0.0 : 1.0;
      for (int a = 3; a < 6; ++a) r[a] = turning ? 1.0 : lever;
    } else if (k >= 0) {
      r[k] = prismatic[l] ? (turning ? 0.0 : 1.0) : (turning ? 1.0 : lever);
    }
    lever += step[l];
  }
  return r;
}

Vec Space::Impl::frame_rates(pinocchio::FrameIndex f, bool turning) const {
  const pinocchio::Frame& frame = model.frames[f];
  return point_rates(static_cast<int>(frame.parentJoint), frame.placement.translation(), turning);
}

// The mass-weighted rates of the joints' inertia centres.
Vec Space::Impl::com_rates() const {
  Vec com = Vec::Zero(n());
  const double mass = pinocchio::computeTotalMass(model);
  for (int j = 1; j < static_cast<int>(model.njoints) && mass > 0; ++j)
    com += (model.inertias[j].mass() / mass) * point_rates(j, model.inertias[j].lever(), false);
  return com;
}

void Space::Impl::build_rates() {
  rates_stale = false;
  if (coord_of.size() != model.njoints) prepare_sweeps();
  certifiable = joints_unsupported.empty() && !batched();
  guarded.clear();
  if (!certifiable) return;
  std::vector<Vec> rows, guards;
  auto add = [&](const Rows& t) {  // false: t has no certificate
    const std::size_t before = guards.size();
    if (!t.rates(*this, rows, guards)) return false;
    if (guards.size() > before) guarded.push_back(&t);
    return true;
  };
  for (const auto& t : terms)
    if (!add(*t)) return void(certifiable = false);
  for (const auto& c : inequalities)
    if (!add(*c)) return void(certifiable = false);
  rows.insert(rows.end(), guards.begin(), guards.end());
  rates.resize(static_cast<long>(rows.size()), n());
  for (std::size_t r = 0; r < rows.size(); ++r) rates.row(static_cast<long>(r)) = rows[r].transpose();
}

// After state_check(q, limit) passed at state i: the slack of each rate row there.
void Space::Impl::note_evaluated(long i, double limit) {
  evaluated = i;
  slack.resize(rates.rows());
  for (int r = 0; r < m; ++r) slack[r] = limit * tolerance[r] - std::abs(state_F[r]);
  for (int r = 0; r < g; ++r) slack[m + r] = -state_G[r];
  double* guard = slack.data() + m + g;
  for (const Rows* t : guarded) guard += t->guard_slack(*this, guard);
}

// Whether state i of the path whose cumulative variation is var passes the equalities and built-in inequalities
// by the rates from the latest evaluated state (a margin of 1e-12 plus 1e-9 of the bound for rounding).
bool Space::Impl::certified(const double* var, long i) {
  if (evaluated < 0 || !certifiable) return false;
  const int nn = n();
  const Eigen::Map<const Vec> now(var + i * nn, nn), then(var + evaluated * nn, nn);
  bound.noalias() = rates * (now - then);
  return ((bound * (1.0 + 1e-9)).array() + 1e-12 <= slack.array()).all();
}

// ---------------------------------------------------------------- Certified sweeps
// A span: consecutive dense states x_i..x_j of a path (the polyline through them is the path itself). Its test
// inflates every sphere by a bound on how far it can move from the middle state x_m over the span; if nothing
// inflated touches, every configuration of the span is collision-free, so every state of it is.
//
// The bound (a "holder" is a ball B = {c + u : |u| <= r} fixed in joint j's frame: a sphere's centre, r = 0, or
// a ball holding a whole geometry). For a point x of B and an active coordinate k moving joint l (an ancestor
// of j or j itself), |dx/dq_k| <= rate_k at every configuration:
//  - revolute l (continuous too): dx/dq_k = a_l x (x - o_l), a_l the unit axis through l's origin o_l, so
//    |dx/dq_k| <= |x - o_l|. From l's frame to x the chain is l's rotation, then for each joint i after l down to
//    j the fixed placement P_i and i's motion X_i, then c + u; rotations keep lengths, so by the triangle
//    inequality |x - o_l| <= sum_i |translation(P_i X_i)| + |c| + r =: lever_l, with |translation(P_i X_i)| =
//    |P_i's translation| for a revolute i, that plus max |q_i| over its limits for a prismatic one, and the
//    constant |translation(P_i X_i(reference))| for a locked joint of any type. Configuration-independent.
//  - prismatic l: dx/dq_k = l's unit axis, rate 1.
//  - the floating base's x, y, z: rate 1; yaw, pitch, roll (R = Rz Ry Rx): dR/d(yaw) R^T = [z]x,
//    dR/d(pitch) R^T = [Rz y]x, dR/d(roll) R^T = [Rz Ry x]x, each an elementary rotation about a unit axis
//    through the base origin: rate lever_base as for a revolute joint.
// Along the polyline from x_m to a state s, q moves by straight pieces, so |x(s) - x(x_m)| <= integral |dx/dt|
// <= sum_k rate_k * TV_k(m..s), TV_k the total variation of coordinate k between the two states; with
// d_k = max(TV_k(i..m), TV_k(m..j)), D = sum_k rate_k d_k bounds the motion over the whole span.
// Two holders A, B (a pair of geometries): their distance does not change under a rigid motion of both, and
// every joint that supports both (the deepest common one, c, and its ancestors: "common") moves both rigidly.
// In c's frame only the other joints move them, so the distance changes by at most D_A' + D_B', the sums over
// non-common coordinates. Hence a sphere pair (i, j) stays apart over the span when
//   |w_i - w_j| > r_i + r_j + D_i' + D_j'   at the middle state,
// a sphere i and a primitive b when dist(w_i, b) > r_i + D_i' + D_b' (D_b: b's holding ball), and two convex
// hulls (exact pairs; each holds its geometry) when their distance exceeds the pair's security margin +
// HULL_MARGIN + D_A' + D_B' (coal's test with that margin: the per-state mid phase's slack). Since every
// sphere set and hull holds its geometry, no state of a certified span collides for coal.
// First order, tighter still where the joints' motions cancel (a constrained hand): with c_k(q) the velocity of
// x per unit q_k (a column of x's Jacobian) and delta(s) = q(s) - q(m),
//   x(s) - x(m) = J(m) delta(s) + integral (c_k(q(t)) - c_k(q(m))) dq_k(t),
// and |c_k(q(t)) - c_k(q(m))| <= E_k: c_k is, in k's frame, a x (x^k - o_k) (revolute; a prismatic joint's: a),
// which changes by at most B_k = sum_{k' deeper} lever_k' d_k', turned by the rotation of k's frame, at most
// Theta_k = sum of d over the rotating coordinates at k and above (rotations compose: angles add; the base's
// yaw, pitch, roll axes turn with yaw and pitch too: twice that for them); so E_k = lever_k Theta_k + B_k
// (prismatic: Theta_k; the base's x, y, z: 0). |J(m) delta(s)| is convex along each straight piece of the
// polyline: its largest value is at a vertex (the span's ends, the path's waypoints inside it). A point of the
// ball, x + u, moves by at most r sum_{rotating k} d_k more. Hence
//   D <= max_vertices |J(m) delta| + sum_k d_k E_k + r sum_{rotating k} d_k,
// over the non-common coordinates for a pair (in the common joint's frame, whose own rotation cancels in |.|);
// the smaller of this and the rate bound is used.
// Computed once per span and shared (chain()): every term is affine in what differs between holders. A column
// is c_k(x) = a_k + b_k x x (revolute or prismatic: k's world Jacobian column, linear part at the origin and
// angular part; the base's x, y, z: a unit vector; its yaw, pitch, roll: axis x (x - o_base)), so over the
// coordinates below depth p, J(m) delta = A_p + B_p x x with A_p, B_p sums over the joints of the chain, the
// same for every holder of that joint; and lever_k = rho + L_k (rho = |c| + r, L_k the joints' steps between k
// and the holder's joint), so the rate bound is rho sum_rot d + sum_rot L d + sum_lin d and sum_k d_k E_k is
// s0 + s1 rho likewise (lin: prismatic and the base's x, y, z). Per holder that leaves |A_p + B_p x x| at each
// vertex and a few products. (A tightening of the rates at the middle state, min(lever_k, its exact speed there
// + r + the deeper joints' reach), was given up: it cost a norm per coordinate and holder and, on 10 planned
// paths each of talos reach, panda wall and maze, PR2 dual-arm and drinkcan, changed 2 sweep tests in all, on the
// dual-arm paths.)
// First tests, sound for the same reasons: a holder's rate bound over every coordinate (prefix sums per joint, at
// least its bound at any depth) before its tails; a sphere whose grown ball clears the grown ball holding the other
// geometry clears each of that geometry's grown spheres (the holding ball's bound covers every point of it).
// (Holder, ChainSums and the sweeps' members: space_impl.hpp.)

// The per-joint data of the bound (and of the constraint's rates); joints_unsupported says why not when an active
// joint is not revolute, prismatic or the floating base.
void Space::Impl::prepare_sweeps() {
  const int nj = static_cast<int>(model.njoints);
  joints_unsupported.clear();
  coord_of.assign(nj, -1);
  prismatic.assign(nj, false);
  step.assign(nj, 0.0);
  pinocchio::Data ref(model);
  pinocchio::forwardKinematics(model, ref, full);  // locked joints at the reference
  const int offset = floating ? 6 : 0;
  for (int j = 1; j < nj; ++j) {
    const auto& joint = model.joints[j];
    const std::string kind = joint.shortname();
    int coord = -1;
    if (floating && joint.idx_q() == base_q) coord = 0;
    for (std::size_t i = 0; i < active.size(); ++i)
      if (active[i].idx_q == joint.idx_q()) coord = offset + static_cast<int>(i);
    coord_of[j] = coord;
    const bool revolute = kind.rfind("JointModelR", 0) == 0;
    const bool slider = kind.rfind("JointModelP", 0) == 0 && kind != "JointModelPlanar";
    const bool base = kind == "JointModelFreeFlyer";
    if (coord < 0) {
      step[j] = ref.liMi[j].translation().norm();
    } else if (revolute || slider) {
      prismatic[j] = slider;
      step[j] = model.jointPlacements[j].translation().norm() +
                (slider ? std::max(std::abs(lower[coord]), std::abs(upper[coord])) : 0.0);
      if (slider && !std::isfinite(step[j])) joints_unsupported = "prismatic joint " + model.names[j] + " has infinite limits";
    } else if (base && coord == 0 && floating) {
      step[j] = model.jointPlacements[j].translation().norm();
    } else {
      joints_unsupported = "joint " + model.names[j] + " (" + kind + ") is neither revolute, prismatic nor the base";
    }
  }
}

// A ball (centre c, radius r) fixed in joint j's frame.
Space::Impl::Holder Space::Impl::holder_of(int j, const Eigen::Vector3d& c, double r) const {
  Holder h;
  h.joint = j;
  h.depth = static_cast<int>(model.supports[j].size());
  h.center = c;
  h.radius = r;
  h.rho = c.norm() + r;
  return h;
}

// Holders of every sphere (centre) and of every geometry (a ball holding it: its spheres' bounding ball, else
// the ball around its local AABB), and the deepest common joint of every collision pair.
void Space::Impl::build_holders() {
  prepare_sweeps();
  sweep_unavailable = joints_unsupported;
  rates_stale = true;
  const std::size_t S = sphere_joint.size(), ng = geom.ngeoms;
  sphere_holder.clear();
  long offset = 0;
  for (std::size_t s = 0; s < S; ++s) {
    sphere_holder.push_back(holder_of(sphere_joint[s], Eigen::Vector3d(sphere_center.row(s).transpose()), 0.0));
    sphere_holder.back().offset = offset;
    offset += sphere_holder.back().depth + 1;
  }
  sphere_tails.assign(offset, 0.0);
  sphere_spans.assign(offset, -1);
  geometry_holder.clear();
  offset = 0;
  for (std::size_t g = 0; g < ng; ++g) {
    const pinocchio::GeometryObject& o = geom.geometryObjects[g];
    const int j = static_cast<int>(o.parentJoint);
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    double r = 0.0;
    if (!spheres_of[g].empty()) {
      c = bound_center[g];
      r = bound_radius[g];
    } else if (j > 0 && o.geometry) {
      o.geometry->computeLocalAABB();
      c = o.placement.act(Eigen::Vector3d(o.geometry->aabb_center));
      r = o.geometry->aabb_radius;
      if (!std::isfinite(c.norm() + r)) sweep_unavailable = "geometry " + o.name + " is unbounded";
    }
    geometry_holder.push_back(holder_of(j, c, r));
    geometry_holder.back().offset = offset;
    offset += geometry_holder.back().depth + 1;
  }
  geometry_tails.assign(offset, 0.0);
  geometry_spans.assign(offset, -1);
  max_depth = 1;
  for (std::size_t j = 0; j < model.supports.size(); ++j)
    max_depth = std::max(max_depth, static_cast<int>(model.supports[j].size()));
  const std::size_t nj = model.njoints;
  joint_rot.assign(nj, 0.0);
  joint_lin.assign(nj, 0.0);
  joint_slide.assign(nj, 0.0);
  joint_turn.assign(nj, 0.0);
  up_rot.assign(nj, 0.0);
  up_lin.assign(nj, 0.0);
  up_step.assign(nj, 0.0);
  up_step_rot.assign(nj, 0.0);
  chain_sums.assign(nj * (max_depth + 1), ChainSums());
  room = 0;
  pair_common.clear();
  for (const auto& pair : geom.collisionPairs) {
    const auto& a = model.supports[geom.geometryObjects[pair.first].parentJoint];
    const auto& b = model.supports[geom.geometryObjects[pair.second].parentJoint];
    int p = 0;
    while (p + 1 < static_cast<int>(std::min(a.size(), b.size())) && a[p + 1] == b[p + 1]) ++p;
    pair_common.push_back(p);
  }
}

// The per-joint terms of the span whose middle state is q (span_variation done): collision kinematics and joint
// Jacobians there, joint_a, joint_b, joint_rot, joint_lin, joint_slide, joint_turn; older sums and tails stale.
void Space::Impl::begin_span(const double* q) {
  place_kinematics(q, true);
  ++span_id;
  const int nj = static_cast<int>(model.njoints), V = static_cast<int>(span_vertices.size()), nn = n();
  if (V > room) {
    room = std::max(V, 2 * room);
    joint_a.assign(static_cast<std::size_t>(nj) * room, Eigen::Vector3d::Zero());
    joint_b.assign(joint_a.size(), Eigen::Vector3d::Zero());
    chain_a.assign(chain_sums.size() * room, Eigen::Vector3d::Zero());
    chain_b.assign(chain_a.size(), Eigen::Vector3d::Zero());
  }
  const double* qm = span_states + span_mid * nn;
  Eigen::Vector3d axes[3];  // the base's yaw, pitch, roll axes at the middle state (world)
  if (floating) {
    axes[0] = Eigen::Vector3d::UnitZ();
    axes[1] = zyx(qm[3], 0.0, 0.0).col(1);
    axes[2] = zyx(qm[3], qm[4], 0.0).col(0);
  }
  for (int l = 1; l < nj; ++l) {
    Eigen::Vector3d* a = &joint_a[static_cast<std::size_t>(l) * room];
    Eigen::Vector3d* b = &joint_b[static_cast<std::size_t>(l) * room];
    double rot = 0.0, lin = 0.0, slide = 0.0;
    const int k = coord_of[l];
    for (int v = 0; v < V; ++v) a[v] = b[v] = Eigen::Vector3d::Zero();
    if (k >= 0 && floating && k == 0) {  // the base: x, y, z, then yaw, pitch, roll about axes through o
      const Eigen::Vector3d o = cdata.oMi[l].translation();
      for (int c = 0; c < 6; ++c) {
        const double d = span_d[c];
        if (d == 0) continue;
        if (c < 3) lin += d;
        else rot += d;
        const Eigen::Vector3d ca = c < 3 ? Eigen::Vector3d::Unit(c) : o.cross(axes[c - 3]);
        for (int v = 0; v < V; ++v) {
          const double delta = span_states[span_vertices[v] * nn + c] - qm[c];
          a[v] += ca * delta;
          if (c >= 3) b[v] += axes[c - 3] * delta;
        }
      }
    } else if (k >= 0 && span_d[k] != 0) {  // world Jacobian column: linear part at the origin, angular part
      const auto J = cdata.J.col(model.joints[l].idx_v());
      const Eigen::Vector3d head = J.head<3>(), tail = J.tail<3>();
      (prismatic[l] ? slide : rot) = span_d[k];
      lin += slide;
      for (int v = 0; v < V; ++v) {
        const double delta = span_states[span_vertices[v] * nn + k] - qm[k];
        a[v] = head * delta;
        b[v] = tail * delta;
      }
    }
    joint_rot[l] = rot;
    joint_lin[l] = lin;
    joint_slide[l] = slide;
    const int up = static_cast<int>(model.parents[l]);
    joint_turn[l] = joint_turn[up] + rot;
    up_rot[l] = up_rot[up] + rot;
    up_lin[l] = up_lin[up] + lin;
    up_step[l] = up_step[up] + step[l];
    up_step_rot[l] = up_step_rot[up] + up_step[l] * rot;
  }
  geometry_rate.resize(geometry_holder.size());
  for (std::size_t g = 0; g < geometry_holder.size(); ++g) geometry_rate[g] = rate_bound(geometry_holder[g]);
}

// Holder h's rate bound over every coordinate, whatever the pair (>= its tail at any depth): rho sum_rot d +
// sum_rot L d + sum_lin d with L = up_step[j] - up_step[l]. A cheap first test: pairs it clears need no tails.
double Space::Impl::rate_bound(const Holder& h) const {
  const int j = h.joint;
  return h.rho * up_rot[j] + up_step[j] * up_rot[j] - up_step_rot[j] + up_lin[j];
}

// The sums over joint j's supports at depth >= p for the current span (see ChainSums); A_p, B_p per vertex at
// chain_a, chain_b[(j (max_depth + 1) + p) room].
const Space::Impl::ChainSums& Space::Impl::chain(int j, int p) {
  const std::size_t key = static_cast<std::size_t>(j) * (max_depth + 1) + p;
  ChainSums& c = chain_sums[key];
  if (c.span == span_id) return c;
  c = ChainSums();
  c.span = span_id;
  const int V = static_cast<int>(span_vertices.size());
  Eigen::Vector3d* A = &chain_a[key * room];
  Eigen::Vector3d* B = &chain_b[key * room];
  for (int v = 0; v < V; ++v) A[v] = B[v] = Eigen::Vector3d::Zero();
  const auto& supports = model.supports[j];
  double L = 0.0;  // the steps between the joint at depth and j: its lever is rho + L
  for (int depth = static_cast<int>(supports.size()) - 1; depth >= p; --depth) {
    const int l = static_cast<int>(supports[depth]);
    if (coord_of[l] >= 0) {
      // E_k = tau lever_k Theta_k + the deeper coordinates' rate bound (tau: 2 for the base's angles; the
      // prismatic's: Theta_k), Theta_k = joint_turn[l]
      const double tau = floating && coord_of[l] == 0 ? 2.0 : 1.0, turn = joint_turn[l], rot = joint_rot[l];
      c.s1 += rot * (tau * turn + c.rot);
      c.s0 += rot * (tau * L * turn + c.lin) + joint_slide[l] * turn;
      c.rot += rot;
      c.lin += L * rot + joint_lin[l];
      const Eigen::Vector3d* a = &joint_a[static_cast<std::size_t>(l) * room];
      const Eigen::Vector3d* b = &joint_b[static_cast<std::size_t>(l) * room];
      for (int v = 0; v < V; ++v) {
        A[v] += a[v];
        B[v] += b[v];
      }
    }
    L += step[l];
  }
  return c;
}

// The motion bound of holder h (its centre at x at the middle state) over the span's coordinates below depth p:
// the smaller of the rate bound and the first-order one (see above).
double Space::Impl::motion_bound(const Holder& h, const Eigen::Vector3d& x, int p) {
  const ChainSums& c = chain(h.joint, p);
  const std::size_t key = (static_cast<std::size_t>(h.joint) * (max_depth + 1) + p) * room;
  double first = 0.0;
  for (std::size_t v = 0; v < span_vertices.size(); ++v)
    first = std::max(first, (chain_a[key + v] + chain_b[key + v].cross(x)).squaredNorm());
  const double rates = h.rho * c.rot + c.lin;
  return std::min(rates, std::sqrt(first) + c.s0 + c.s1 * h.rho + c.rot * h.radius);
}

// Sphere s's bound relative to a pair whose deepest common joint is at depth common (s placed: world[s]).
double Space::Impl::sphere_tail(int s, int common) {
  const Holder& h = sphere_holder[s];
  const long at = h.offset + common + 1;
  if (sphere_spans[at] != span_id) {
    sphere_spans[at] = span_id;
    sphere_tails[at] = motion_bound(h, world[s], common + 1);
  }
  return sphere_tails[at];
}

// The same for the ball holding geometry g.
double Space::Impl::geometry_tail(int g, int common) {
  const Holder& h = geometry_holder[g];
  const long at = h.offset + common + 1;
  if (geometry_spans[at] != span_id) {
    geometry_spans[at] = span_id;
    const Eigen::Vector3d x = spheres_of[g].empty() ? cdata.oMi[h.joint].act(h.center) : bound_world[g];
    geometry_tails[at] = motion_bound(h, x, common + 1);
  }
  return geometry_tails[at];
}

// The span [i, j] of states (rows of n; var: their cumulative variation; turns: per state, whether the polyline
// may turn there, null: at every state), middle state m: d (n,), its vertices.
void Space::Impl::span_variation(const double* states, const double* var, const char* turns, long i, long m, long j) {
  const int nn = n();
  for (int k = 0; k < nn; ++k)
    span_d[k] = std::max(var[m * nn + k] - var[i * nn + k], var[j * nn + k] - var[m * nn + k]);
  span_states = states;
  span_mid = m;
  span_vertices.assign(1, i);
  for (long t = i + 1; t < j; ++t)
    if (!turns || turns[t]) span_vertices.push_back(t);
  if (j > i) span_vertices.push_back(j);
}

// Whether every configuration of the span whose middle state is q is collision-free (span_variation done):
// per pair, as the per-state check, the spheres first, then the convex outer shapes; the pair that stopped the
// latest span first (neighbouring spans fail on the same pair).
bool Space::Impl::span_free(const double* q) {
  begin_span(q);
  if (last_stop >= 0 && !pair_apart(tests[last_stop])) return false;
  for (std::size_t k = 0; k < tests.size(); ++k)
    if (static_cast<long>(k) != last_stop && !pair_apart(tests[k])) {
      last_stop = static_cast<long>(k);
      return false;
    }
  return true;
}

bool Space::Impl::pair_apart(const PairTest& t) {
  const int common = pair_common[t.pair];
  if (t.kind == SPHERES_SPHERES && spheres_apart(t, common)) return true;
  if (t.kind == SPHERES_PRIMITIVE && sphere_primitive_apart(t, common)) return true;
  // a pair left to coal whose geometries both have spheres (tight: spheres touching while the meshes are apart in
  // many states): its grown spheres first all the same, a certificate as good, cheaper than the hulls' GJK
  if (t.kind == EXACT_PAIR && !spheres_of[t.a].empty() && !spheres_of[t.b].empty() && spheres_apart(t, common)) return true;
  return outers_apart(t.pair, common);
}

// The spheres of a pair (kind 0), each grown by its motion bound, do not touch. A sphere of t.a whose grown ball
// clears the grown ball holding t.b clears each of t.b's grown spheres (that ball's bound covers every point of
// it): its row is skipped.
bool Space::Impl::spheres_apart(const PairTest& t, int common) {
  const Eigen::Vector3d& cb = bound_world[t.b];
  const double far = bound_radius[t.a] + bound_radius[t.b] + geometry_rate[t.a] + geometry_rate[t.b];
  if ((bound_world[t.a] - cb).squaredNorm() > far * far) return true;
  const double apart = (bound_world[t.a] - cb).norm() - bound_radius[t.a] - bound_radius[t.b];
  const double rb = bound_radius[t.b] + geometry_tail(t.b, common);
  if (apart > geometry_tail(t.a, common) + geometry_tail(t.b, common)) return true;
  place(t.a);
  place(t.b);
  grown.clear();  // t.b's spheres' grown radii, when first needed
  for (int i : spheres_of[t.a]) {
    const double gap = (world[i] - cb).norm() - sphere_radius[i] - rb;
    if (gap > rate_bound(sphere_holder[i])) continue;
    const double tail = sphere_tail(i, common), ri = sphere_radius[i] + tail;
    if (gap > tail) continue;
    if (grown.empty())
      for (int j : spheres_of[t.b]) grown.push_back(sphere_radius[j] + sphere_tail(j, common));
    const double* rj = grown.data();
    for (int j : spheres_of[t.b]) {
      const double reach = ri + *rj++;
      if ((world[i] - world[j]).squaredNorm() <= reach * reach) return false;
    }
  }
  return true;
}

// The spheres of t.a, grown, do not touch the primitive t.b grown by its own motion bound (kind 1).
bool Space::Impl::sphere_primitive_apart(const PairTest& t, int common) {
  const pinocchio::SE3& pose = pose_of(t.b);
  if (beyond(t.b, pose, bound_world[t.a],
             bound_radius[t.a] + geometry_rate[t.a] + geometry_rate[t.b]))
    return true;
  const double grow_b = geometry_tail(t.b, common);
  if (beyond(t.b, pose, bound_world[t.a], bound_radius[t.a] + geometry_tail(t.a, common) + grow_b)) return true;
  place(t.a);
  for (int i : spheres_of[t.a])
    if (!beyond(t.b, pose, world[i], sphere_radius[i] + sphere_tail(i, common) + grow_b)) return false;
  return true;
}

// The convex outer shapes of collision pair k are farther apart than its security margin + HULL_MARGIN + both
// geometries' motion bounds (false when a geometry has none).
bool Space::Impl::outers_apart(std::size_t k, int common) {
  const pinocchio::CollisionPair& pair = geom.collisionPairs[k];
  const coal::CollisionGeometry* oa = outer_of(static_cast<int>(pair.first));
  const coal::CollisionGeometry* ob = outer_of(static_cast<int>(pair.second));
  if (!oa || !ob) return false;
  if (!placed_geometries) {
    pinocchio::updateGeometryPlacements(model, cdata, geom, *geom_data);
    placed_geometries = true;
  }
  ++tally->hull_tests;
  coal::CollisionRequest request = outer_requests[k];
  request.security_margin +=
      geometry_tail(static_cast<int>(pair.first), common) + geometry_tail(static_cast<int>(pair.second), common);
  coal::CollisionResult result;
  coal::collide(oa, pinocchio::toCoalTransform3s(geom_data->oMg[pair.first]), ob,
                pinocchio::toCoalTransform3s(geom_data->oMg[pair.second]), request, result);
  outer_requests[k].updateGuess(result);
  return !result.isCollision();
}

void Space::set_sweeps(bool on) { impl_->sweeps_on = on; }
void Space::prepare() {
  if (impl_->rates_stale) impl_->build_rates();
}
bool Space::sweeps() const { return impl_->sweeps_ready(); }
std::string Space::sweep_report() const {
  return impl_->sphere_joint.empty() ? "no sphere models" : impl_->sweep_unavailable;
}

// Cumulative |dq| along states (k, n): var (k, n), row 0 zeros.
static void cumulative_variation(const double* states, long k, int nn, std::vector<double>& var) {
  var.assign(k * nn, 0.0);
  for (long i = 1; i < k; ++i)
    for (int c = 0; c < nn; ++c)
      var[i * nn + c] = var[(i - 1) * nn + c] + std::abs(states[i * nn + c] - states[(i - 1) * nn + c]);
}

bool Space::sweep_free(const double* states, int k) {
  Impl& p = *impl_;
  if (!p.sweeps_ready()) throw std::runtime_error("no certified sweeps: " + sweep_report());
  if (k < 1) throw std::invalid_argument("a span needs at least one state");
  cumulative_variation(states, k, n(), p.variation);
  p.span_variation(states, p.variation.data(), nullptr, 0, k / 2, k - 1);
  ++counts.sweep_checks;
  return p.span_free(states + static_cast<long>(k / 2) * n());
}

std::vector<double> Space::sweep_bounds(const double* states, int k, int common, bool rates) {
  Impl& p = *impl_;
  if (!p.sweeps_ready()) throw std::runtime_error("no certified sweeps: " + sweep_report());
  if (k < 1) throw std::invalid_argument("a span needs at least one state");
  cumulative_variation(states, k, n(), p.variation);
  p.span_variation(states, p.variation.data(), nullptr, 0, k / 2, k - 1);
  p.begin_span(states + static_cast<long>(k / 2) * n());
  std::vector<double> out;
  for (int g = 0; g < static_cast<int>(p.spheres_of.size()); ++g) p.place(g);
  for (std::size_t s = 0; s < p.sphere_joint.size(); ++s)
    out.push_back(rates ? p.rate_bound(p.sphere_holder[s])
                  : common + 1 > p.sphere_holder[s].depth ? NAN
                                                          : p.sphere_tail(static_cast<int>(s), std::max(common, -1)));
  return out;
}

PathCheck Space::validate_path(const double* path, int K, bool certify) {
  const int nn = n();
  const double res = impl_->resolution;
  if (K < 1) throw std::invalid_argument("a path needs at least one waypoint");
  PathCheck out{true, 0.0, -1, VALID, -1, 0};
  // the dense states in order and the segment each lies on (the last waypoint: segment K - 2)
  std::vector<double> states;
  std::vector<int> segment;
  for (int seg = 0; seg + 1 < K; ++seg) {
    Eigen::Map<const Vec> a(path + static_cast<long>(seg) * nn, nn), b(path + static_cast<long>(seg + 1) * nn, nn);
    const int steps = std::max(1, static_cast<int>(std::ceil((b - a).norm() / res)));
    for (int j = 0; j < steps; ++j) {
      const Vec s = a + (static_cast<double>(j) / steps) * (b - a);
      states.insert(states.end(), s.data(), s.data() + nn);
      segment.push_back(seg);
    }
  }
  if (K >= 1) {
    states.insert(states.end(), path + static_cast<long>(K - 1) * nn, path + static_cast<long>(K) * nn);
    segment.push_back(std::max(K - 2, 0));
  }
  const long M = static_cast<long>(segment.size()), chunk = 4096;  // chunk: rows per callback (batched())
  const int pp = impl_->p;
  std::vector<double> v, G;
  Impl& p = *impl_;
  if (certify && p.rates_stale) p.build_rates();
  certify = certify && p.certifiable;
  p.evaluated = -1;
  if (p.sweeps_ready()) return sweep_path(states, segment, certify);
  if (certify) cumulative_variation(states.data(), M, nn, p.variation);
  for (long i = 0; i < M; ++i) {
    const double* q = states.data() + i * nn;
    if (batched() && i % chunk == 0) {
      const long c = std::min(chunk, M - i);
      v.resize(c);
      violations(q, c, v.data());
      G.resize(c * pp);
      if (pp) inequalities(q, c, G.data());
    }
    int c = VALID;
    if (!within_limits(q)) c = LIMITS;
    else {
      bool hold = true;
      double vi = 0.0;  // certified: passed by the rates, not evaluated
      if (batched()) {
        vi = v[i % chunk];
      } else if (!certify || !p.certified(p.variation.data(), i)) {
        vi = p.state_check(q, 1.0, hold);
        if (certify && vi <= 1.0 && hold) p.note_evaluated(i, 1.0);
      }
      out.worst = std::max(out.worst, vi);
      if (vi > 1.0) c = CONSTRAINT;
      else if (!(batched() ? inequalities_hold(q) : hold)) c = INEQUALITY;
      else if (pp && *std::max_element(G.begin() + (i % chunk) * pp, G.begin() + (i % chunk + 1) * pp) > 0)
        c = INEQUALITY;
      else if (!collision_free(q)) c = COLLISION;
    }
    if (c != VALID) {
      out.valid = false;
      out.first_invalid = i;
      out.reason = c;
      out.segment = segment[i];
      out.states = i + 1;
      return out;
    }
  }
  out.states = M;
  return out;
}

// validate_path with certified sweeps: chunk by chunk, the states' limits, constraint and inequalities in order up
// to the first failure f (as state by state), then collisions before f by spans: a span [i, i + L) is tested at
// once (Impl::span_free); certified, the next span starts after it with L doubled; not certified, L is halved
// (the left part first); a single state gets the exact per-state check. States are thus cleared strictly left to
// right, so the first colliding state found is the path's first, and the report equals the state-by-state one
// (worst: over the states up to the first invalid one, as there).
PathCheck Space::sweep_path(const std::vector<double>& states, const std::vector<int>& segment, bool certify) {
  Impl& p = *impl_;
  const int nn = n(), pp = p.p;
  const long M = static_cast<long>(segment.size());
  const long chunk = batched() ? 4096 : 128;  // states whose constraint tests run before their collision tests
  PathCheck out{true, 0.0, -1, VALID, -1, 0};
  cumulative_variation(states.data(), M, nn, p.variation);
  std::vector<char> turns(M, false);  // the path's waypoints
  for (long i = 0; i < M; ++i) turns[i] = i == 0 || i == M - 1 || segment[i] != segment[i - 1];
  std::vector<double> v(chunk), G;
  std::vector<char> limits_ok(chunk);
  long L = 8;  // span length, carried from span to span
  bool grow = true;  // whether a certified span doubles L: not right after a refusal (the length that passed is kept)
  for (long s0 = 0; s0 < M; s0 += chunk) {
    const long s1 = std::min(M, s0 + chunk);
    const double* q0 = states.data() + s0 * nn;
    if (batched()) {
      violations(q0, s1 - s0, v.data());
      G.resize((s1 - s0) * pp);
      if (pp) inequalities(q0, s1 - s0, G.data());
    }
    long f = s1;  // first state failing a test other than collision
    int reason = VALID;
    for (long i = s0; i < s1 && f == s1; ++i) {
      const double* q = states.data() + i * nn;
      limits_ok[i - s0] = within_limits(q);
      if (!limits_ok[i - s0]) reason = LIMITS;
      else {
        bool hold = true;
        if (certify && p.certified(p.variation.data(), i)) {
          v[i - s0] = 0.0;  // passed by the rates, not evaluated
        } else if (!batched()) {
          v[i - s0] = p.state_check(q, 1.0, hold);
          if (certify && v[i - s0] <= 1.0 && hold) p.note_evaluated(i, 1.0);
        }
        if (v[i - s0] > 1.0) reason = CONSTRAINT;
        else if (!(batched() ? inequalities_hold(q) : hold)) reason = INEQUALITY;
        else if (pp && *std::max_element(G.begin() + (i - s0) * pp, G.begin() + (i - s0 + 1) * pp) > 0)
          reason = INEQUALITY;
      }
      if (reason != VALID) f = i;
    }
    long hit = -1;  // first colliding state before f
    for (long i = s0; i < f;) {
      L = std::min(L, f - i);
      if (L <= 1) {
        if (!collision_free(states.data() + i * nn)) {
          hit = i;
          break;
        }
        ++i;
        L = 2;
        grow = false;
        continue;
      }
      const long j = i + L - 1, m = (i + j) / 2;
      p.span_variation(states.data(), p.variation.data(), turns.data(), i, m, j);
      ++counts.sweep_checks;
      if (p.span_free(states.data() + m * nn)) {
        i += L;
        if (grow) L *= 2;
        grow = true;
      } else {
        L /= 2;
        grow = false;
      }
    }
    const long last = hit >= 0 ? hit : f < s1 ? f : s1 - 1;  // the last state checked
    for (long i = s0; i <= last; ++i)
      if (limits_ok[i - s0]) out.worst = std::max(out.worst, v[i - s0]);
    if (hit >= 0 || f < s1) {
      out.valid = false;
      out.first_invalid = last;
      out.reason = hit >= 0 ? static_cast<int>(COLLISION) : reason;
      out.segment = segment[last];
      out.states = last + 1;
      return out;
    }
  }
  out.states = M;
  return out;
}

}  // namespace mgcore
