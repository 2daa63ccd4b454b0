// The constrained space's private parts (core.hpp declares Space): Space::Impl with its members and the small types
// it holds, shared by space.cpp (construction, the compiled and callback terms), builtin_terms.cpp (the built-in
// terms and their table), terms.cpp (residuals, Jacobians, inequalities, projection), collision.cpp (sphere broad
// phase, hull mid phase, the validity rule) and sweeps.cpp (validate_path, certified constraints and certified
// sweeps). Only those five files include it.
#pragma once

#include "core.hpp"

#include <pinocchio/collision/broadphase-manager.hpp>
#include <pinocchio/geometry.hpp>
#include <pinocchio/multibody.hpp>
#include <pinocchio/spatial.hpp>

#include <coal/broadphase/broadphase_dynamic_AABB_tree.h>
#include <coal/collision_data.h>
#include <coal/collision_object.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

namespace mgcore {

using Manager = pinocchio::BroadPhaseManagerTpl<coal::DynamicAABBTreeCollisionManager>;
using Matrix6x = Eigen::Matrix<double, 6, Eigen::Dynamic>;
constexpr double HULL_MARGIN = 1e-4;  // m: convex outer shapes closer than this go on to coal's exact test

// The types Space::Impl holds and the helpers that more than one of the space's files use (named, not anonymous:
// Impl is one class in all four files).
namespace space_detail {

// A compiled user residual or inequality (Space::add_expression) and the leaves it reads, filled per state.
struct Compiled {
  Expression expression;
  Leaves leaves;
  explicit Compiled(Expression e) : expression(std::move(e)), leaves(expression.leaves()) {}
};

// The space's constraint as rows: equality terms stack F(q) = 0 (m rows), inequalities G(q) <= 0 (g rows), each in
// the order added. The built-in ones (builtin_terms.cpp, by name from Space::add_term), a compiled expression and a
// Python callback (terms.cpp) are subclasses; the space evaluates them through these methods only.
struct Rows {
  virtual ~Rows() = default;
  virtual int rows() const = 0;
  // Its rows at q (forward kinematics done, and the centre of mass when needs_com()).
  virtual void values(Space::Impl& p, const double* q, double* out) const = 0;
  virtual bool needs_com() const { return false; }
  // Certified sweeps (sweeps.cpp): push each row's speed bound per active coordinate, (n,), to rows, and rows
  // that keep those bounds sound to guards (a pose's rotation angle below 1 rad); false: no certificate.
  virtual bool rates(const Space::Impl&, std::vector<Vec>&, std::vector<Vec>&) const { return false; }
  // The guards' slack at the latest state values() saw (one per guard that rates pushed); returns how many.
  virtual int guard_slack(const Space::Impl&, double*) const { return 0; }
};

// An equality term: rows of F, with their Jacobian rows over the active coordinates.
struct Term : Rows {
  // Its rows of F and of J (joint Jacobians done; J: its first row's start, n per row).
  virtual void jacobian(Space::Impl& p, const double* q, double* F, double* J) const = 0;
  // A Python callback's index in Impl::callbacks (its rows are filled per batch); -1: evaluated here.
  virtual int callback() const { return -1; }
};

// An inequality term: rows of G <= 0 (checked after the equalities; no Jacobian).
struct Inequality : Rows {};

// A compiled user residual or inequality (Space::add_expression, add_expression_inequality; terms.cpp).
struct ExpressionTerm final : Term {
  mutable Compiled compiled;  // its leaves are filled per state
  explicit ExpressionTerm(Expression e) : compiled(std::move(e)) {}
  int rows() const override { return compiled.expression.rows(); }
  void values(Space::Impl& p, const double* q, double* F) const override;
  void jacobian(Space::Impl& p, const double* q, double* F, double* J) const override;
};
struct ExpressionInequality final : Inequality {
  mutable Compiled compiled;
  explicit ExpressionInequality(Expression e) : compiled(std::move(e)) {}
  int rows() const override { return compiled.expression.rows(); }
  void values(Space::Impl& p, const double* q, double* G) const override;
};

// A Python callback's rows (Space::add_callback): filled by Impl::fill_callbacks per batch, not per state.
struct CallbackTerm final : Term {
  int index, count;  // in Impl::callbacks; its rows
  CallbackTerm(int index, int count) : index(index), count(count) {}
  int rows() const override { return count; }
  void values(Space::Impl&, const double*, double*) const override {}
  void jacobian(Space::Impl&, const double*, double*, double*) const override {}
  int callback() const override { return index; }
};

// R = Rz(yaw) Ry(pitch) Rx(roll), manifoldgen.robot's floating-base rotation.
inline Eigen::Matrix3d zyx(double yaw, double pitch, double roll) {
  return (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

// A scene primitive the spheres are tested against (world pose fixed at construction of the pair list).
enum ShapeKind : int { NO_SHAPE = -1, BOX, SPHERE, CYLINDER };
struct Shape {
  ShapeKind kind = NO_SHAPE;  // size: a box's half sides, a sphere's radius, a cylinder's radius and half length (z)
  Eigen::Vector3d size = Eigen::Vector3d::Zero();
  double outer = 0.0;  // circumradius: the shape lies within this distance of its origin
};

// Distance from point p (in the shape's frame) to the shape (0 inside).
inline double shape_distance(const Shape& s, const Eigen::Vector3d& p) {
  if (s.kind == BOX) return (p.cwiseAbs() - s.size).cwiseMax(0.0).norm();
  if (s.kind == SPHERE) return std::max(p.norm() - s.size[0], 0.0);
  const double radial = std::max(std::hypot(p[0], p[1]) - s.size[0], 0.0);
  const double axial = std::max(std::abs(p[2]) - s.size[1], 0.0);
  return std::hypot(radial, axial);
}

// How the sphere test treats one collision pair: spheres against spheres, spheres against a
// primitive, or the exact coal test of that pair.
enum PairKind : int { SPHERES_SPHERES, SPHERES_PRIMITIVE, EXACT_PAIR };
struct PairTest {
  PairKind kind;
  int a, b;  // geometry indices (SPHERES_PRIMITIVE: a has spheres, b is the primitive)
  std::size_t pair;  // index in the geometry model's collision pairs (EXACT_PAIR)
};

}  // namespace space_detail

using namespace space_detail;

// Functions defined in the class: small ones on the per-state and per-pair paths that more than one file calls.
// Declared inline and defined in a .cpp file: called from that file only (elsewhere they would not link), inline as
// they were when the class defined them all, so the optimizer inlines them as it did then.
struct Space::Impl {
  // ---------------------------------------------------------------- The robot and the constraint terms (terms.cpp)
  pinocchio::Model model;
  pinocchio::Data data, cdata;  // constraint kinematics; collision kinematics
  pinocchio::GeometryModel geom;
  std::unique_ptr<pinocchio::GeometryData> geom_data;
  std::unique_ptr<Manager> manager;
  std::vector<Active> active;  // the one-coordinate joints (after the base's six coordinates when floating)
  bool floating = false;       // the first six coordinates are the free flyer's (x, y, z, yaw, pitch, roll)
  int base_q = 0, base_v = 0;  // where the free flyer sits in pinocchio's q and v
  Eigen::Matrix<double, 6, 6> base_map;  // d(free-flyer v) / d(base coordinates) at the latest Jacobian's q
  std::vector<std::unique_ptr<const Term>> terms;
  std::vector<std::unique_ptr<const Inequality>> inequalities;
  int g = 0;
  bool com_needed = false;  // some inequality reads the centre of mass
  Vec full, lower, upper, tolerance;
  Matrix6x Ja, Jb;
  double margin, resolution;  // set by the constructor from the Python space
  int m = 0;
  // Python callbacks (Space::add_callback, set_inequalities)
  std::vector<Residuals> callbacks;
  Inequalities inequality;
  int p = 0;
  bool native_terms = false;  // some term is built in (forward kinematics needed): set by add
  std::vector<double> state_F, state_G;  // state_check's rows at the latest state it evaluated
  Counters* tally = nullptr;  // the Space's counters (evaluations, hull and mesh tests are counted here)

  // Append a term: its rows to m, and whether forward kinematics is needed.
  void add(std::unique_ptr<const Term> t) {
    m += t->rows();
    native_terms = native_terms || t->callback() < 0;
    terms.push_back(std::move(t));
    rates_stale = true;
  }
  // Append an inequality: its rows to g, and whether the centre of mass is needed.
  void add(std::unique_ptr<const Inequality> c) {
    g += c->rows();
    com_needed = com_needed || c->needs_com();
    inequalities.push_back(std::move(c));
    rates_stale = true;
  }
  pinocchio::FrameIndex frame_of(int id, const char* what) const {  // a term's frame id, checked
    if (id < 0 || id >= static_cast<int>(model.nframes))
      throw std::invalid_argument(std::string(what) + " frame id out of range");
    return static_cast<pinocchio::FrameIndex>(id);
  }

  const Eigen::VectorXd& to_full(const double* q) {
    const int offset = floating ? 6 : 0;
    if (floating) set_base(q);
    for (std::size_t i = 0; i < active.size(); ++i) {
      const Active& a = active[i];
      const double x = q[offset + i];
      if (a.nq == 2) {
        full[a.idx_q] = std::cos(x);
        full[a.idx_q + 1] = std::sin(x);
      } else {
        full[a.idx_q] = x;
      }
    }
    return full;
  }

  int n() const { return static_cast<int>(active.size()) + (floating ? 6 : 0); }

  // Jacobian row (n) from a row over pinocchio's v (rowvec(i): its i-th entry); the base columns through
  // base_map (computed by map_base for the same q).
  template <typename Row>
  void put_row(double* J, const Row& rowvec) {
    const int offset = floating ? 6 : 0;
    for (std::size_t i = 0; i < active.size(); ++i) J[offset + i] = rowvec(active[i].idx_v);
    if (!floating) return;
    double v[6];
    for (int k = 0; k < 6; ++k) v[k] = rowvec(base_v + k);
    for (int c = 0; c < 6; ++c) {
      double sum = 0.0;
      for (int k = 0; k < 6; ++k) sum += v[k] * base_map(k, c);
      J[c] = sum;
    }
  }

  // The floating base: pinocchio's free flyer at (x, y, z) with the quaternion of Rz(yaw) Ry(pitch) Rx(roll).
  void set_base(const double* q) {
    const Eigen::Quaterniond r(zyx(q[3], q[4], q[5]));
    full.segment<3>(base_q) = Eigen::Map<const Eigen::Vector3d>(q);
    full[base_q + 3] = r.x();
    full[base_q + 4] = r.y();
    full[base_q + 5] = r.z();
    full[base_q + 6] = r.w();
  }

  // Python callback terms or inequalities: rows are evaluated in batches (Space::batched)
  bool batched() const { return !callbacks.empty() || p > 0; }

  inline void expression_rows(Compiled& c, const double* q, double* F, double* J);
  inline void fill_residual(const double* q, double* F);
  inline void fill_jacobian(const double* q, double* F, double* J);
  void fill_callbacks(const double* q, long B, Counters& counts, double* F, double* J);
  inline void map_base(const double* q);
  inline void fill_inequality(const double* q, double* G);
  inline void inequality_rows(const double* q, double* G);
  double state_check(const double* q, double limit, bool& hold);  // also called by collision.cpp and sweeps.cpp

  // ---------------------------------------------------------------- Spheres and convex outer shapes (collision.cpp)
  std::vector<int> sphere_joint;
  RowMat sphere_center;  // (S, 3) in the joint frame
  Vec sphere_radius;
  std::vector<std::vector<int>> spheres_of;  // per geometry: its sphere indices
  std::vector<Eigen::Vector3d> world;         // per sphere: world centre (latest state)
  // per geometry with spheres: a ball holding them all (centre in the joint frame, radius), tested first
  std::vector<Eigen::Vector3d> bound_center, bound_world;
  std::vector<double> bound_radius;
  std::vector<int> bound_joint;
  std::vector<char> placed_spheres;  // per geometry: its world centres are up to date
  std::vector<PairTest> tests;
  std::vector<Shape> shapes;  // per geometry
  // per geometry: what a pair's mid phase tests before coal's exact test (a mesh's convex hull, built on
  // first use; a primitive itself), and whether it was looked up
  std::vector<std::shared_ptr<coal::CollisionGeometry>> outer;
  std::vector<char> outer_ready;
  // per collision pair: the mid phase's request, warm-started from the pair's latest GJK (successive states
  // are close; the guess changes how fast GJK converges, not its verdict)
  std::vector<coal::CollisionRequest> outer_requests;
  bool placed_geometries = false;  // geom_data's placements are those of the latest collision kinematics
  std::vector<pinocchio::SE3> shape_pose;  // per geometry (primitives)
  std::vector<char> shape_placed;

  // A primitive's world pose at the latest collision kinematics (computed once per state).
  const pinocchio::SE3& pose_of(int b) {
    if (!shape_placed[b]) {
      const pinocchio::GeometryObject& g = geom.geometryObjects[b];
      shape_pose[b] = g.parentJoint ? cdata.oMi[g.parentJoint] * g.placement : g.placement;
      shape_placed[b] = true;
    }
    return shape_pose[b];
  }

  // Whether the world point x lies farther than r from primitive b (at pose): farther than its circumradius + r
  // from its origin (no transform), else by the exact distance.
  bool beyond(int b, const pinocchio::SE3& pose, const Eigen::Vector3d& x, double r) const {
    const double reach = shapes[b].outer + r;
    if ((x - pose.translation()).squaredNorm() > reach * reach) return true;
    return shape_distance(shapes[b], pose.actInv(x)) > r;
  }

  void place(int g) {
    if (placed_spheres[g]) return;
    placed_spheres[g] = true;
    for (int s : spheres_of[g]) world[s] = cdata.oMi[sphere_joint[s]].act(Eigen::Vector3d(sphere_center.row(s).transpose()));
  }

  const coal::CollisionGeometry* outer_of(int g);                  // also called by sweeps.cpp
  void place_kinematics(const double* q, bool jacobians = false);  // also called by sweeps.cpp
  inline bool pair_collides(std::size_t k);
  inline bool pairs_collide(const double* q, bool& flagged);
  inline bool spheres_touch(int a, int b) const;
  inline bool spheres_touch_shape(int a, int b, const pinocchio::SE3& pose) const;
  inline bool spheres_hit(const double* q);

  // ---------------------------------------------------------------- Certified constraints (sweeps.cpp)
  static constexpr double LOG_RATE = 0.5 / 0.479425538604203;  // (a/2)/sin(a/2) at a = 1 rad
  RowMat rates;                        // (rows, n): m equality rows, g inequality rows, then the terms' guards
  std::vector<const Rows*> guarded;    // the terms with guard rows, in guard-row order
  bool rates_stale = true, certifiable = false;
  Vec slack;                           // (rows,) at the latest evaluated state
  Vec bound;                           // (rows,) certified()'s, kept to spare an allocation per state
  long evaluated = -1;                 // the latest evaluated state of the path being checked (-1: none yet)

  // (n,) speed bounds per unit speed of each coordinate, over every configuration (also called by the terms'
  // rates in builtin_terms.cpp): of a point at c in joint j's frame (turning: of the frame's rotation), of a
  // frame, of the centre of mass.
  Vec point_rates(int j, const Eigen::Vector3d& c, bool turning) const;
  Vec frame_rates(pinocchio::FrameIndex f, bool turning) const;
  Vec com_rates() const;
  inline void build_rates();
  inline void note_evaluated(long i, double limit);
  inline bool certified(const double* var, long i);

  // ---------------------------------------------------------------- Certified sweeps (sweeps.cpp, with the proof)
  struct Holder {
    int joint = 0, depth = 1;                          // its joint and the joint's supports
    Eigen::Vector3d center = Eigen::Vector3d::Zero();  // in the joint's frame
    double radius = 0.0, rho = 0.0;                    // rho = |center| + radius
    long offset = 0;                                   // of its tails in the tails buffers (depth + 1 entries)
  };
  // The latest span's sums over the coordinates of joint l and its ancestors' chain (chain(j, p): over j's
  // supports at depth >= p): rot (d of rotating coordinates), lin (rate-1 coordinates' d plus L d of rotating
  // ones: the rate bound is rho rot + lin), s0 + s1 rho = sum_k d_k E_k.
  struct ChainSums {
    double rot = 0.0, lin = 0.0, s0 = 0.0, s1 = 0.0;
    long span = -1;  // the span they were summed for
  };
  const double* span_states = nullptr;                // the path's dense states (rows of n)
  long span_mid = 0;                                  // the current span's middle state
  std::vector<long> span_vertices;                    // its states where the polyline may turn (ends, waypoints)
  long span_id = 0;                                   // counts spans: cached sums and tails of older ones are stale
  bool sweeps_on = true;
  std::string sweep_unavailable;   // why no sweep ("" when available)
  std::string joints_unsupported;  // why no joint data for the bounds (prepare_sweeps; "" when there is)
  std::vector<Holder> sphere_holder, geometry_holder;
  std::vector<double> sphere_tails, geometry_tails;  // per holder: tail[p + 1] = its motion bound below depth p
  std::vector<long> sphere_spans, geometry_spans;    // the span each tail was computed for
  std::vector<int> pair_common;                      // per collision pair: depth of the deepest common joint
  std::vector<double> step;                          // per joint: |translation(P_i X_i)| bound (see sweeps.cpp)
  std::vector<int> coord_of;                         // per joint: its active coordinate (-1 locked; base: 0)
  std::vector<char> prismatic;                       // per joint
  Vec span_d;                                        // (n,) d_k of the current span
  std::vector<double> variation;                     // (M, n) cumulative |dq| along the path being checked
  // per span, per joint l: its coordinates' (a_k, b_k) delta_v,k summed, per vertex v ((njoints, room));
  // their d summed: rotating, rate 1, prismatic; turn: rotating d of l and its ancestors
  std::vector<Eigen::Vector3d> joint_a, joint_b;
  std::vector<double> joint_rot, joint_lin, joint_slide, joint_turn;
  // and over l and its ancestors: rot, lin, step, step * rot summed (a holder's rate bound over every coordinate)
  std::vector<double> up_rot, up_lin, up_step, up_step_rot;
  // per (joint j, depth p), summed when first asked for in a span: ChainSums and A_p, B_p per vertex
  std::vector<ChainSums> chain_sums;  // (njoints, max_depth + 1)
  std::vector<Eigen::Vector3d> chain_a, chain_b;  // (njoints, max_depth + 1, room)
  int max_depth = 1, room = 0;  // the longest chain of supports; vertices per span the buffers hold
  std::vector<double> geometry_rate;  // per geometry: its holder's rate_bound in the current span
  long last_stop = -1;  // the test that stopped the latest uncertified span
  std::vector<double> grown;  // spheres_apart's grown radii of the second geometry's spheres

  bool sweeps_ready() const { return sweeps_on && sweep_unavailable.empty() && !sphere_joint.empty(); }

  void build_holders();  // also called by collision.cpp (set_spheres)
  inline void prepare_sweeps();
  inline Holder holder_of(int j, const Eigen::Vector3d& c, double r) const;
  inline void begin_span(const double* q);
  inline double rate_bound(const Holder& h) const;
  inline const ChainSums& chain(int j, int p);
  inline double motion_bound(const Holder& h, const Eigen::Vector3d& x, int p);
  inline double sphere_tail(int s, int common);
  inline double geometry_tail(int g, int common);
  inline void span_variation(const double* states, const double* var, const char* turns, long i, long m, long j);
  inline bool span_free(const double* q);
  inline bool pair_apart(const PairTest& t);
  inline bool spheres_apart(const PairTest& t, int common);
  inline bool sphere_primitive_apart(const PairTest& t, int common);
  inline bool outers_apart(std::size_t k, int common);
};

}  // namespace mgcore
