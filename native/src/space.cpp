// The constrained space in C++ (see core.hpp): manifoldgen.space.ConstrainedSpace's rule with the
// constraint terms of constraints/pose.py, rotation.py (a pose term without position axes) and
// closed_chain.py, the projection of constraints/projection.py, and a sphere-model collision test.
// Whole-body (the block "Whole-body terms"): a floating base as manifoldgen.robot's six Euler
// coordinates, orientation.py's and joint_linear.py's terms, and inequalities (balance.py's CoM margin,
// orientation.py's hemisphere); balance.py's equalities are pose terms. Any other constraint (a user's) runs as a
// compiled expression (expression.cpp: its residual and inequalities traced by manifoldgen/constraints/trace.py),
// or, where it could not be traced, through Python callbacks on batches of configurations (manifoldgen/native.py
// ConstraintCallback).
#include "core.hpp"

#include <pinocchio/algorithm/center-of-mass.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/geometry.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/collision/broadphase.hpp>
#include <pinocchio/collision/broadphase-manager.hpp>
#include <pinocchio/collision/collision.hpp>
#include <pinocchio/serialization.hpp>
#include <pinocchio/spatial.hpp>

#include <coal/BVH/BVH_model.h>
#include <coal/broadphase/broadphase_dynamic_AABB_tree.h>
#include <coal/collision.h>
#include <coal/shape/convex.h>
#include <coal/shape/geometric_shapes.h>
#include <pinocchio/collision/coal-pinocchio-conversions.hpp>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <map>
#include <mutex>
#include <sstream>
#include <stdexcept>

namespace mgcore {

using Manager = pinocchio::BroadPhaseManagerTpl<coal::DynamicAABBTreeCollisionManager>;
using Matrix6x = Eigen::Matrix<double, 6, Eigen::Dynamic>;
constexpr double HULL_MARGIN = 1e-4;  // m: convex outer shapes closer than this go on to coal's exact test

namespace {

// A compiled user residual or inequality (Space::add_expression) and the leaves it reads, filled per state.
struct Compiled {
  Expression expression;
  Leaves leaves;
  explicit Compiled(Expression e) : expression(std::move(e)), leaves(expression.leaves()) {}
};

// What a residual term is: one per built-in constraint kind (Space::add_pose ... add_linear), a Python callback
// (add_callback) or a compiled expression (add_expression).
enum TermKind : int { POSE_TERM, CHAIN_TERM, SPHERE_TERM, ORIENTATION_TERM, LINEAR_TERM, CALLBACK_TERM, EXPRESSION_TERM };
// What an inequality is: the CoM's support polygon, a hemisphere of directions, or a compiled expression.
enum InequalityKind : int { COM_POLYGON, HEMISPHERE, EXPRESSION_INEQUALITY };

struct Term {
  TermKind kind;  // sphere: offset = its centre, y = (radius)
  pinocchio::FrameIndex frame, frame_b;
  Eigen::Matrix3d rotation;
  std::vector<int> position_axes, orientation_axes;
  Vec y;                   // pose: the conditioned positions; linear: y
  Eigen::Vector3d offset;  // chain: d * axis
  Eigen::Vector3d axis = Eigen::Vector3d::Zero();                    // orientation: the frame's axis
  Eigen::Matrix<double, 2, 3> basis = Eigen::Matrix<double, 2, 3>::Zero();  // orientation: e1, e2
  RowMat A;                                                          // linear: (r, n)
  int callback = -1, callback_rows = 0;  // callback: its index in Impl::callbacks, its residual rows
  std::shared_ptr<Compiled> compiled;    // expression
  int rows() const {
    return kind == POSE_TERM ? static_cast<int>(position_axes.size() + orientation_axes.size())
           : kind == CHAIN_TERM ? 6
           : kind == ORIENTATION_TERM ? 2
           : kind == LINEAR_TERM ? static_cast<int>(A.rows())
           : kind == CALLBACK_TERM ? callback_rows
           : kind == EXPRESSION_TERM ? compiled->expression.rows()
                       : 1;
  }
};

// An inequality G(q) <= 0 (whole-body terms).
struct Inequality {
  InequalityKind kind;
  pinocchio::FrameIndex frame = 0;
  Eigen::Vector3d axis = Eigen::Vector3d::Zero(), direction = Eigen::Vector3d::Zero();
  RowMat normals;  // (H, 2)
  Vec bounds;      // (H,)
  std::shared_ptr<Compiled> compiled;  // expression
  int rows() const {
    return kind == COM_POLYGON ? static_cast<int>(normals.rows()) : kind == EXPRESSION_INEQUALITY ? compiled->expression.rows() : 1;
  }
};

// R = Rz(yaw) Ry(pitch) Rx(roll), manifoldgen.robot's floating-base rotation.
Eigen::Matrix3d zyx(double yaw, double pitch, double roll) {
  return (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

// The convex hull of a mesh (with its triangles, for coal's hill-climbing support), built once per mesh content
// and process: qhull costs about 1 ms a mesh, and every plan builds a new Space. Null when qhull fails or the
// mesh cannot have a hull (fewer than 4 vertices, no triangles, a non-finite vertex: qhull would crash on it):
// such a mesh's pairs go from the spheres straight to coal. (buildConvexHull's return value says whether the mesh
// was convex itself, not whether the hull was built: a concave mesh's hull holds it all the same.)
std::shared_ptr<coal::ConvexBase> mesh_hull(coal::BVHModelBase& mesh) {
  static std::mutex guard;
  static std::map<std::string, std::shared_ptr<coal::ConvexBase>> built;
  if (!mesh.vertices || mesh.num_vertices < 4 || mesh.num_tris < 1) return nullptr;
  for (unsigned int i = 0; i < mesh.num_vertices; ++i)
    if (!(*mesh.vertices)[i].allFinite()) return nullptr;
  std::string key(reinterpret_cast<const char*>(mesh.vertices->data()), mesh.num_vertices * sizeof(coal::Vec3s));
  std::lock_guard<std::mutex> hold(guard);
  auto found = built.find(key);
  if (found != built.end()) return found->second;
  std::shared_ptr<coal::ConvexBase> hull;
  try {  // coal refuses some meshes with an exception (e.g. "Too many neighbors": a vertex of over 255 edges)
    mesh.buildConvexHull(true, "Qt");
    hull = mesh.convex;
  } catch (const std::exception&) {
    try {  // the hull's facets as qhull merges them, not triangulated: fewer edges per vertex (centauro's pelvis)
      mesh.buildConvexHull(false, "");
      hull = mesh.convex;
    } catch (const std::exception&) {
    }
  }
  built.emplace(std::move(key), hull);
  return hull;
}

// A scene primitive the spheres are tested against (world pose fixed at construction of the pair list).
enum ShapeKind : int { NO_SHAPE = -1, BOX, SPHERE, CYLINDER };
struct Shape {
  ShapeKind kind = NO_SHAPE;  // size: a box's half sides, a sphere's radius, a cylinder's radius and half length (z)
  Eigen::Vector3d size = Eigen::Vector3d::Zero();
  double outer = 0.0;  // circumradius: the shape lies within this distance of its origin
};

// Distance from point p (in the shape's frame) to the shape (0 inside).
double shape_distance(const Shape& s, const Eigen::Vector3d& p) {
  if (s.kind == BOX) return (p.cwiseAbs() - s.size).cwiseMax(0.0).norm();
  if (s.kind == SPHERE) return std::max(p.norm() - s.size[0], 0.0);
  const double radial = std::max(std::hypot(p[0], p[1]) - s.size[0], 0.0);
  const double axial = std::max(std::abs(p[2]) - s.size[1], 0.0);
  return std::hypot(radial, axial);
}

Shape shape_of(const pinocchio::GeometryObject& g) {
  Shape s;
  if (auto box = std::dynamic_pointer_cast<coal::Box>(g.geometry)) {
    s.kind = BOX;
    s.size = box->halfSide;
    s.outer = s.size.norm();
  } else if (auto sphere = std::dynamic_pointer_cast<coal::Sphere>(g.geometry)) {
    s.kind = SPHERE;
    s.size[0] = sphere->radius;
    s.outer = s.size[0];
  } else if (auto cyl = std::dynamic_pointer_cast<coal::Cylinder>(g.geometry)) {
    s.kind = CYLINDER;
    s.size[0] = cyl->radius;
    s.size[1] = cyl->halfLength;
    s.outer = std::hypot(s.size[0], s.size[1]);
  }
  return s;
}

// How the sphere test treats one collision pair: spheres against spheres, spheres against a
// primitive, or the exact coal test of that pair.
enum PairKind : int { SPHERES_SPHERES, SPHERES_PRIMITIVE, EXACT_PAIR };
struct PairTest {
  PairKind kind;
  int a, b;  // geometry indices (SPHERES_PRIMITIVE: a has spheres, b is the primitive)
  std::size_t pair;  // index in the geometry model's collision pairs (EXACT_PAIR)
};

}  // namespace

struct Space::Impl {
  pinocchio::Model model;
  pinocchio::Data data, cdata;  // constraint kinematics; collision kinematics
  pinocchio::GeometryModel geom;
  std::unique_ptr<pinocchio::GeometryData> geom_data;
  std::unique_ptr<Manager> manager;
  std::vector<Active> active;  // the one-coordinate joints (after the base's six coordinates when floating)
  bool floating = false;       // the first six coordinates are the free flyer's (x, y, z, yaw, pitch, roll)
  int base_q = 0, base_v = 0;  // where the free flyer sits in pinocchio's q and v
  Eigen::Matrix<double, 6, 6> base_map;  // d(free-flyer v) / d(base coordinates) at the latest Jacobian's q
  std::vector<Term> terms;
  std::vector<Inequality> inequalities;
  int g = 0;
  bool com_needed = false;
  Vec full, lower, upper, tolerance;
  Matrix6x Ja, Jb;
  double margin = 0.05, resolution = 0.005;
  int m = 0;
  // spheres
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
  // Python callbacks (Space::add_callback, set_inequalities)
  std::vector<Residuals> callbacks;
  // The callback terms' rows of F (B, m) and, when J is not null, of J (B, m, n) at q (B, n).
  void fill_callbacks(const double* q, long B, Counters& counts, double* F, double* J);
  Inequalities inequality;
  int p = 0;
  bool native_terms = false;  // some term is built in (forward kinematics needed): set by add

  // Append a term: its rows to m, and whether forward kinematics is needed.
  void add(const Term& t) {
    m += t.rows();
    terms.push_back(t);
    rates_stale = true;
    native_terms = native_terms || t.kind != CALLBACK_TERM;
  }

  // A compiled expression's rows at q (forward kinematics done; with J, the joint Jacobians too): its frames'
  // placements (and Jacobians, mapped to the active coordinates as put_row does) and the centre of mass when it
  // reads it, then its program. J: its first row's start, n per row (null: values only).
  void expression_rows(Compiled& c, const double* q, double* F, double* J) {
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
  // per geometry: what a pair's mid phase tests before coal's exact test (a mesh's convex hull, built on
  // first use; a primitive itself), and whether it was looked up
  std::vector<std::shared_ptr<coal::CollisionGeometry>> outer;
  std::vector<char> outer_ready;
  // per collision pair: the mid phase's request, warm-started from the pair's latest GJK (successive states
  // are close; the guess changes how fast GJK converges, not its verdict)
  std::vector<coal::CollisionRequest> outer_requests;
  bool placed_geometries = false;  // geom_data's placements are those of the latest collision kinematics
  Counters* tally = nullptr;       // the Space's counters (hull and mesh tests are counted here)

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

  // Residual rows of every term from data's joint placements (forward kinematics done).
  void fill_residual(const double* q, double* F) {
    int row = 0;
    for (const Term& t : terms) {
      if (t.kind == CALLBACK_TERM) {  // filled by the batch's callback
        row += t.rows();
        continue;
      }
      if (t.kind == EXPRESSION_TERM) {
        expression_rows(*t.compiled, q, F + row, nullptr);
        row += t.rows();
        continue;
      }
      if (t.kind == ORIENTATION_TERM || t.kind == LINEAR_TERM) {
        row += whole_body_residual(t, q, F + row);
        continue;
      }
      const pinocchio::SE3& A = pinocchio::updateFramePlacement(model, data, t.frame);
      if (t.kind == SPHERE_TERM) {
        F[row++] = (A.translation() - t.offset).norm() - t.y[0];
      } else if (t.kind == POSE_TERM) {
        for (std::size_t k = 0; k < t.position_axes.size(); ++k)
          F[row++] = A.translation()[t.position_axes[k]] - t.y[k];
        const Eigen::Vector3d err = pinocchio::log3(Eigen::Matrix3d(t.rotation.transpose() * A.rotation()));
        for (int a : t.orientation_axes) F[row++] = err[a];
      } else {
        const pinocchio::SE3& B = pinocchio::updateFramePlacement(model, data, t.frame_b);
        const Eigen::Vector3d rel = A.rotation().transpose() * (B.translation() - A.translation()) - t.offset;
        const Eigen::Vector3d err = pinocchio::log3(
            Eigen::Matrix3d(t.rotation.transpose() * A.rotation().transpose() * B.rotation()));
        for (int i = 0; i < 3; ++i) F[row++] = rel[i];
        for (int i = 0; i < 3; ++i) F[row++] = err[i];
      }
    }
  }

  // J (m, n) row-major from the frame Jacobians (computeJointJacobians done).
  void fill_jacobian(const double* q, double* F, double* J) {
    const int nn = n();
    if (floating) map_base(q);
    auto put = [&](int row, const auto& rowvec) { put_row(J + static_cast<long>(row) * nn, rowvec); };  // rowvec over nv
    int row = 0;
    for (const Term& t : terms) {
      if (t.kind == CALLBACK_TERM) {  // filled by the batch's callback
        row += t.rows();
        continue;
      }
      if (t.kind == EXPRESSION_TERM) {
        expression_rows(*t.compiled, q, F + row, J + static_cast<long>(row) * nn);
        row += t.rows();
        continue;
      }
      if (t.kind == ORIENTATION_TERM || t.kind == LINEAR_TERM) {
        row += whole_body_jacobian(t, q, F + row, J + static_cast<long>(row) * nn);
        continue;
      }
      const pinocchio::SE3& A = pinocchio::updateFramePlacement(model, data, t.frame);
      Ja.setZero();
      pinocchio::getFrameJacobian(model, data, t.frame, pinocchio::LOCAL_WORLD_ALIGNED, Ja);
      if (t.kind == SPHERE_TERM) {
        const Eigen::Vector3d d = A.translation() - t.offset;
        const double r = d.norm();
        F[row] = r - t.y[0];
        put(row++, (d / std::max(r, 1e-12)).transpose() * Ja.topRows<3>());
      } else if (t.kind == POSE_TERM) {
        double theta;
        const Eigen::Vector3d err =
            pinocchio::log3(Eigen::Matrix3d(t.rotation.transpose() * A.rotation()), theta);
        Eigen::Matrix3d Jlog;
        pinocchio::Jlog3(theta, err, Jlog);
        const Eigen::Matrix<double, 3, Eigen::Dynamic> Jrot = Jlog * A.rotation().transpose() * Ja.bottomRows<3>();
        for (std::size_t k = 0; k < t.position_axes.size(); ++k) {
          F[row] = A.translation()[t.position_axes[k]] - t.y[k];
          put(row++, Ja.row(t.position_axes[k]));
        }
        for (int a : t.orientation_axes) {
          F[row] = err[a];
          put(row++, Jrot.row(a));
        }
      } else {
        const pinocchio::SE3& B = pinocchio::updateFramePlacement(model, data, t.frame_b);
        Jb.setZero();
        pinocchio::getFrameJacobian(model, data, t.frame_b, pinocchio::LOCAL_WORLD_ALIGNED, Jb);
        const Eigen::Matrix3d RaT = A.rotation().transpose();
        const Eigen::Vector3d r = B.translation() - A.translation();
        const Eigen::Vector3d rel = RaT * r - t.offset;
        double theta;
        const Eigen::Vector3d err =
            pinocchio::log3(Eigen::Matrix3d(t.rotation.transpose() * RaT * B.rotation()), theta);
        Eigen::Matrix3d Jlog;
        pinocchio::Jlog3(theta, err, Jlog);
        const Eigen::Matrix<double, 3, Eigen::Dynamic> Jpos =
            RaT * (Jb.topRows<3>() - Ja.topRows<3>() + pinocchio::skew(r) * Ja.bottomRows<3>());
        const Eigen::Matrix<double, 3, Eigen::Dynamic> Jrot =
            Jlog * B.rotation().transpose() * (Jb.bottomRows<3>() - Ja.bottomRows<3>());
        for (int i = 0; i < 3; ++i) {
          F[row] = rel[i];
          put(row++, Jpos.row(i));
        }
        for (int i = 0; i < 3; ++i) {
          F[row] = err[i];
          put(row++, Jrot.row(i));
        }
      }
    }
  }

  // ---------------------------------------------------------------- Whole-body terms
  // The floating base: pinocchio's free flyer at (x, y, z) with the quaternion of Rz(yaw) Ry(pitch) Rx(roll).
  void set_base(const double* q) {
    const Eigen::Quaterniond r(zyx(q[3], q[4], q[5]));
    full.segment<3>(base_q) = Eigen::Map<const Eigen::Vector3d>(q);
    full[base_q + 3] = r.x();
    full[base_q + 4] = r.y();
    full[base_q + 5] = r.z();
    full[base_q + 6] = r.w();
  }

  // base_map: the free flyer's v (linear and angular velocity in the base frame) per unit change of
  // (x, y, z, yaw, pitch, roll): v_lin = R^T dp, omega = R^T E dtheta, E's columns the world axes of
  // yaw (z), pitch (Rz y) and roll (Rz Ry x).
  void map_base(const double* q) {
    const Eigen::Matrix3d Rz = zyx(q[3], 0.0, 0.0), Rzy = zyx(q[3], q[4], 0.0), R = zyx(q[3], q[4], q[5]);
    Eigen::Matrix3d E;
    E.col(0) = Eigen::Vector3d::UnitZ();
    E.col(1) = Rz.col(1);
    E.col(2) = Rzy.col(0);
    base_map.setZero();
    base_map.topLeftCorner<3, 3>() = R.transpose();
    base_map.bottomRightCorner<3, 3>() = R.transpose() * E;
  }

  // Rows of an orientation or linear term at q (forward kinematics done); returns their count.
  int whole_body_residual(const Term& t, const double* q, double* F) {
    if (t.kind == LINEAR_TERM) {
      Eigen::Map<Vec>(F, t.A.rows()) = t.A * Eigen::Map<const Vec>(q, n()) - t.y;
      return static_cast<int>(t.A.rows());
    }
    const pinocchio::SE3& A = pinocchio::updateFramePlacement(model, data, t.frame);
    Eigen::Map<Eigen::Vector2d>{F} = t.basis * (A.rotation() * t.axis);
    return 2;
  }

  // The same rows and their Jacobian rows (J: the first row's start, n per row; joint Jacobians done).
  int whole_body_jacobian(const Term& t, const double* q, double* F, double* J) {
    const int nn = n();
    if (t.kind == LINEAR_TERM) {
      Eigen::Map<Vec>(F, t.A.rows()) = t.A * Eigen::Map<const Vec>(q, nn) - t.y;
      Eigen::Map<RowMat>(J, t.A.rows(), nn) = t.A;
      return static_cast<int>(t.A.rows());
    }
    const pinocchio::SE3& A = pinocchio::updateFramePlacement(model, data, t.frame);
    Ja.setZero();
    pinocchio::getFrameJacobian(model, data, t.frame, pinocchio::LOCAL_WORLD_ALIGNED, Ja);
    const Eigen::Vector3d pointing = A.rotation() * t.axis;
    Eigen::Map<Eigen::Vector2d>{F} = t.basis * pointing;
    // d(R axis) = omega x (R axis) = -hat(R axis) omega
    const Eigen::Matrix<double, 2, Eigen::Dynamic> rows = -(t.basis * pinocchio::skew(pointing)) * Ja.bottomRows<3>();
    for (int r = 0; r < 2; ++r) put_row(J + static_cast<long>(r) * nn, rows.row(r));
    return 2;
  }

  // G (g,) at q: the CoM polygon's rows from pinocchio's centre of mass, a hemisphere's from the frame.
  void fill_inequality(const double* q, double* G) {
    if (com_needed) pinocchio::centerOfMass(model, data, to_full(q), false);
    else pinocchio::forwardKinematics(model, data, to_full(q));
    inequality_rows(q, G);
  }

  // G (g,) at q from data's kinematics (and centre of mass when the polygon needs it).
  void inequality_rows(const double* q, double* G) {
    int row = 0;
    for (const Inequality& c : inequalities) {
      if (c.kind == EXPRESSION_INEQUALITY) {
        expression_rows(*c.compiled, q, G + row, nullptr);
      } else if (c.kind == COM_POLYGON) {
        const Eigen::Vector2d com = data.com[0].head<2>();
        Eigen::Map<Vec>(G + row, c.normals.rows()) = c.normals * com - c.bounds;
      } else {
        const pinocchio::SE3& A = pinocchio::updateFramePlacement(model, data, c.frame);
        G[row] = -c.direction.dot(A.rotation() * c.axis);
      }
      row += c.rows();
    }
  }

  // One state's equality violation (max |F_i| / tol_i; 0 without terms) and, when it is within limit, whether the
  // built-in inequalities hold, from one forward kinematics (the centre of mass's pass when the polygon needs it;
  // pinocchio's centerOfMass runs forwardKinematics first, so the residual is the same) where Space::violation and
  // inequalities_hold make one each. Built-in terms only (not batched()); counts the evaluation as residual does.
  std::vector<double> state_F, state_G;
  double state_check(const double* q, double limit, bool& hold) {
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
  static constexpr double LOG_RATE = 0.5 / 0.479425538604203;  // (a/2)/sin(a/2) at a = 1 rad
  RowMat rates;                        // (rows, n): m equality rows, g inequality rows, one angle row per pose
  std::vector<int> angle_terms;        // the poses (term index) with orientation rows, in angle-row order
  bool rates_stale = true, certifiable = false;
  Vec slack;                           // (rows,) at the latest evaluated state
  Vec bound;                           // (rows,) certified()'s, kept to spare an allocation per state
  long evaluated = -1;                 // the latest evaluated state of the path being checked (-1: none yet)

  // (n,) the speed bound of a point at c in joint j's frame (turning: of the frame's rotation) per unit speed of
  // each coordinate, over every configuration.
  Vec point_rates(int j, const Eigen::Vector3d& c, bool turning) const {
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
  Vec frame_rates(pinocchio::FrameIndex f, bool turning) const {
    const pinocchio::Frame& frame = model.frames[f];
    return point_rates(static_cast<int>(frame.parentJoint), frame.placement.translation(), turning);
  }

  void build_rates() {
    rates_stale = false;
    if (coord_of.size() != model.njoints) prepare_sweeps();
    certifiable = joints_unsupported.empty() && !batched();
    angle_terms.clear();
    if (!certifiable) return;
    std::vector<Vec> rows, angles;
    for (std::size_t i = 0; i < terms.size(); ++i) {
      const Term& t = terms[i];
      if (t.kind == POSE_TERM) {
        for (std::size_t k = 0; k < t.position_axes.size(); ++k) rows.push_back(frame_rates(t.frame, false));
        for (std::size_t k = 0; k < t.orientation_axes.size(); ++k) rows.push_back(LOG_RATE * frame_rates(t.frame, true));
        if (!t.orientation_axes.empty()) {
          angle_terms.push_back(static_cast<int>(i));
          angles.push_back(frame_rates(t.frame, true));
        }
      } else if (t.kind == SPHERE_TERM) {
        rows.push_back(frame_rates(t.frame, false));
      } else if (t.kind == ORIENTATION_TERM) {
        for (int k = 0; k < 2; ++k) rows.push_back(t.basis.row(k).norm() * t.axis.norm() * frame_rates(t.frame, true));
      } else if (t.kind == LINEAR_TERM) {
        for (int k = 0; k < t.A.rows(); ++k) rows.push_back(t.A.row(k).cwiseAbs().transpose());
      } else {
        certifiable = false;
        return;
      }
    }
    Vec com = Vec::Zero(n());
    const double mass = pinocchio::computeTotalMass(model);
    for (int j = 1; j < static_cast<int>(model.njoints) && mass > 0; ++j)
      com += (model.inertias[j].mass() / mass) * point_rates(j, model.inertias[j].lever(), false);
    for (const Inequality& c : inequalities)
      if (c.kind == EXPRESSION_INEQUALITY) {
        certifiable = false;
        return;
      }
    for (const Inequality& c : inequalities)
      for (int h = 0; h < c.rows(); ++h)
        rows.push_back(c.kind == COM_POLYGON ? Vec(c.normals.row(h).norm() * com)
                                   : Vec(c.direction.norm() * c.axis.norm() * frame_rates(c.frame, true)));
    rows.insert(rows.end(), angles.begin(), angles.end());
    rates.resize(static_cast<long>(rows.size()), n());
    for (std::size_t r = 0; r < rows.size(); ++r) rates.row(static_cast<long>(r)) = rows[r].transpose();
  }
  // Python callback terms or inequalities: rows are evaluated in batches (Space::batched)
  bool batched() const { return !callbacks.empty() || p > 0; }

  // After state_check(q, limit) passed at state i: the slack of each rate row there.
  void note_evaluated(long i, double limit) {
    evaluated = i;
    slack.resize(rates.rows());
    for (int r = 0; r < m; ++r) slack[r] = limit * tolerance[r] - std::abs(state_F[r]);
    for (int r = 0; r < g; ++r) slack[m + r] = -state_G[r];
    for (std::size_t a = 0; a < angle_terms.size(); ++a) {
      const Term& t = terms[angle_terms[a]];
      const Eigen::Matrix3d R = t.rotation.transpose() * data.oMf[t.frame].rotation();
      slack[m + g + static_cast<long>(a)] = 1.0 - std::acos(std::clamp((R.trace() - 1.0) / 2.0, -1.0, 1.0));
    }
  }
  // Whether state i of the path whose cumulative variation is var passes the equalities and built-in inequalities
  // by the rates from the latest evaluated state (a margin of 1e-12 plus 1e-9 of the bound for rounding).
  bool certified(const double* var, long i) {
    if (evaluated < 0 || !certifiable) return false;
    const int nn = n();
    const Eigen::Map<const Vec> now(var + i * nn, nn), then(var + evaluated * nn, nn);
    bound.noalias() = rates * (now - then);
    return ((bound * (1.0 + 1e-9)).array() + 1e-12 <= slack.array()).all();
  }

  // A geometry's convex outer shape (a mesh's hull with its triangles, for coal's hill-climbing support;
  // a box, sphere, cylinder, capsule or convex itself); null when none.
  const coal::CollisionGeometry* outer_of(int g) {
    if (outer_ready[g]) return outer[g].get();
    outer_ready[g] = true;
    const auto& shape = geom.geometryObjects[g].geometry;
    if (auto mesh = std::dynamic_pointer_cast<coal::BVHModelBase>(shape)) {
      outer[g] = mesh_hull(*mesh);
    } else if (shape && shape->getObjectType() == coal::OT_GEOM) {
      outer[g] = shape;
    }
    return outer[g].get();
  }

  // Exact verdict of one collision pair at the latest collision kinematics: coal's test, after a mid
  // phase on the two geometries' convex outer shapes (each holds its geometry, so outer shapes apart by
  // more than HULL_MARGIN mean geometries apart: the verdict is coal's either way).
  bool pair_collides(std::size_t k) {
    if (!placed_geometries) {
      pinocchio::updateGeometryPlacements(model, cdata, geom, *geom_data);
      placed_geometries = true;
    }
    const pinocchio::CollisionPair& pair = geom.collisionPairs[k];
    const coal::CollisionGeometry* oa = outer_of(static_cast<int>(pair.first));
    const coal::CollisionGeometry* ob = outer_of(static_cast<int>(pair.second));
    if (oa && ob) {
      ++tally->hull_tests;
      coal::CollisionRequest& request = outer_requests[k];
      coal::CollisionResult result;
      coal::collide(oa, pinocchio::toCoalTransform3s(geom_data->oMg[pair.first]), ob,
                    pinocchio::toCoalTransform3s(geom_data->oMg[pair.second]), request, result);
      request.updateGuess(result);
      if (!result.isCollision()) return false;
    }
    ++tally->mesh_tests;
    return pinocchio::computeCollision(geom, *geom_data, static_cast<pinocchio::PairIndex>(k));
  }

  // A primitive's world pose at the latest collision kinematics (computed once per state).
  const pinocchio::SE3& pose_of(int b) {
    if (!shape_placed[b]) {
      const pinocchio::GeometryObject& g = geom.geometryObjects[b];
      shape_pose[b] = g.parentJoint ? cdata.oMi[g.parentJoint] * g.placement : g.placement;
      shape_placed[b] = true;
    }
    return shape_pose[b];
  }
  std::vector<pinocchio::SE3> shape_pose;  // per geometry (primitives)
  std::vector<char> shape_placed;

  // Whether the world point x lies farther than r from primitive b (at pose): farther than its circumradius + r
  // from its origin (no transform), else by the exact distance.
  bool beyond(int b, const pinocchio::SE3& pose, const Eigen::Vector3d& x, double r) const {
    const double reach = shapes[b].outer + r;
    if ((x - pose.translation()).squaredNorm() > reach * reach) return true;
    return shape_distance(shapes[b], pose.actInv(x)) > r;
  }

  // Exact collision test with the sphere models as a per-pair broad phase: a pair whose spheres touch
  // nothing is free; every other pair (spheres touching, exact pairs) gets pair_collides. flagged: some
  // pair's spheres touched (the sphere test alone would have called the state in collision).
  bool pairs_collide(const double* q, bool& flagged) {
    place_kinematics(q);
    flagged = false;
    for (const PairTest& t : tests) {
      if (t.kind == SPHERES_SPHERES) {
        if ((bound_world[t.a] - bound_world[t.b]).norm() > bound_radius[t.a] + bound_radius[t.b]) continue;
        place(t.a);
        place(t.b);
        if (!spheres_touch(t.a, t.b)) continue;
      } else if (t.kind == SPHERES_PRIMITIVE) {
        const pinocchio::SE3& pose = pose_of(t.b);
        if (beyond(t.b, pose, bound_world[t.a], bound_radius[t.a])) continue;
        place(t.a);
        if (!spheres_touch_shape(t.a, t.b, pose)) continue;
      } else if (!spheres_of[t.a].empty() && !spheres_of[t.b].empty()) {
        // a pair left to coal because its spheres often touch while the meshes are apart: where they do not
        // touch, the pair is free all the same (the sphere-only verdict, spheres_hit, still sends it to coal)
        if ((bound_world[t.a] - bound_world[t.b]).norm() > bound_radius[t.a] + bound_radius[t.b]) continue;
        place(t.a);
        place(t.b);
        if (!spheres_touch(t.a, t.b)) continue;
      }
      if (t.kind != 2) flagged = true;
      if (pair_collides(t.pair)) return true;
    }
    return false;
  }

  // Collision kinematics at q, bounding balls placed; sphere centres placed lazily by place().
  // jacobians: the joint Jacobians too (cdata.J, world frame), for the certified sweeps' rates.
  void place_kinematics(const double* q, bool jacobians = false) {
    if (jacobians) pinocchio::computeJointJacobians(model, cdata, to_full(q));
    else pinocchio::forwardKinematics(model, cdata, to_full(q));
    std::fill(placed_spheres.begin(), placed_spheres.end(), false);
    std::fill(shape_placed.begin(), shape_placed.end(), false);
    placed_geometries = false;
    for (std::size_t g = 0; g < bound_joint.size(); ++g)
      if (bound_joint[g] >= 0) bound_world[g] = cdata.oMi[bound_joint[g]].act(bound_center[g]);
  }

  void place(int g) {
    if (placed_spheres[g]) return;
    placed_spheres[g] = true;
    for (int s : spheres_of[g]) world[s] = cdata.oMi[sphere_joint[s]].act(Eigen::Vector3d(sphere_center.row(s).transpose()));
  }

  bool spheres_touch(int a, int b) const {
    for (int i : spheres_of[a])
      for (int j : spheres_of[b])
        if ((world[i] - world[j]).squaredNorm() <= std::pow(sphere_radius[i] + sphere_radius[j], 2)) return true;
    return false;
  }

  bool spheres_touch_shape(int a, int b, const pinocchio::SE3& pose) const {
    for (int i : spheres_of[a])
      if (!beyond(b, pose, world[i], sphere_radius[i])) return true;
    return false;
  }

  // Sphere test of the latest collision kinematics (cdata): true when some tested pair may collide.
  bool spheres_hit(const double* q) {
    place_kinematics(q);
    for (const PairTest& t : tests) {
      if (t.kind == SPHERES_SPHERES) {
        if ((bound_world[t.a] - bound_world[t.b]).norm() > bound_radius[t.a] + bound_radius[t.b]) continue;
        place(t.a);
        place(t.b);
        if (spheres_touch(t.a, t.b)) return true;
      } else if (t.kind == SPHERES_PRIMITIVE) {
        const pinocchio::SE3& pose = pose_of(t.b);
        if (beyond(t.b, pose, bound_world[t.a], bound_radius[t.a])) continue;
        place(t.a);
        if (spheres_touch_shape(t.a, t.b, pose)) return true;
      } else {
        if (!placed_geometries) {
          pinocchio::updateGeometryPlacements(model, cdata, geom, *geom_data);
          placed_geometries = true;
        }
        ++tally->mesh_tests;
        if (pinocchio::computeCollision(geom, *geom_data, static_cast<pinocchio::PairIndex>(t.pair))) return true;
      }
    }
    return false;
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
  std::vector<double> step;                          // per joint: |translation(P_i X_i)| bound (see above)
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

  bool sweeps_ready() const { return sweeps_on && sweep_unavailable.empty() && !sphere_joint.empty(); }

  // The per-joint data of the bound (and of the constraint's rates); joints_unsupported says why not when an active
  // joint is not revolute, prismatic or the floating base.
  void prepare_sweeps() {
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
  Holder holder_of(int j, const Eigen::Vector3d& c, double r) const {
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
  void build_holders() {
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
  void begin_span(const double* q) {
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
  double rate_bound(const Holder& h) const {
    const int j = h.joint;
    return h.rho * up_rot[j] + up_step[j] * up_rot[j] - up_step_rot[j] + up_lin[j];
  }
  std::vector<double> geometry_rate;  // per geometry: its holder's rate_bound in the current span

  // The sums over joint j's supports at depth >= p for the current span (see ChainSums); A_p, B_p per vertex at
  // chain_a, chain_b[(j (max_depth + 1) + p) room].
  const ChainSums& chain(int j, int p) {
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
  double motion_bound(const Holder& h, const Eigen::Vector3d& x, int p) {
    const ChainSums& c = chain(h.joint, p);
    const std::size_t key = (static_cast<std::size_t>(h.joint) * (max_depth + 1) + p) * room;
    double first = 0.0;
    for (std::size_t v = 0; v < span_vertices.size(); ++v)
      first = std::max(first, (chain_a[key + v] + chain_b[key + v].cross(x)).squaredNorm());
    const double rates = h.rho * c.rot + c.lin;
    return std::min(rates, std::sqrt(first) + c.s0 + c.s1 * h.rho + c.rot * h.radius);
  }
  // Sphere s's bound relative to a pair whose deepest common joint is at depth common (s placed: world[s]).
  double sphere_tail(int s, int common) {
    const Holder& h = sphere_holder[s];
    const long at = h.offset + common + 1;
    if (sphere_spans[at] != span_id) {
      sphere_spans[at] = span_id;
      sphere_tails[at] = motion_bound(h, world[s], common + 1);
    }
    return sphere_tails[at];
  }
  // The same for the ball holding geometry g.
  double geometry_tail(int g, int common) {
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
  void span_variation(const double* states, const double* var, const char* turns, long i, long m, long j) {
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
  bool span_free(const double* q) {
    begin_span(q);
    if (last_stop >= 0 && !pair_apart(tests[last_stop])) return false;
    for (std::size_t k = 0; k < tests.size(); ++k)
      if (static_cast<long>(k) != last_stop && !pair_apart(tests[k])) {
        last_stop = static_cast<long>(k);
        return false;
      }
    return true;
  }
  long last_stop = -1;  // the test that stopped the latest uncertified span

  bool pair_apart(const PairTest& t) {
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
  bool spheres_apart(const PairTest& t, int common) {
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
  std::vector<double> grown;

  // The spheres of t.a, grown, do not touch the primitive t.b grown by its own motion bound (kind 1).
  bool sphere_primitive_apart(const PairTest& t, int common) {
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
  bool outers_apart(std::size_t k, int common) {
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
};

Space::Space(const std::string& model_file, const std::string& geometry_file, const Vec& reference,
             const std::vector<Active>& active, const Vec& lower, const Vec& upper, double margin, double resolution)
    : impl_(new Impl) {
  Impl& p = *impl_;
  p.tally = &counts;
  try {
    p.model.loadFromBinary(model_file);
    p.geom.loadFromBinary(geometry_file);
  } catch (const std::exception& e) {
    throw std::runtime_error(std::string("cannot load the serialized robot model: ") + e.what());
  }
  if (reference.size() != p.model.nq) throw std::runtime_error("reference has the wrong size for the model");
  for (std::size_t i = 0; i < active.size(); ++i) {
    if (active[i].nq != FREE_FLYER) {
      p.active.push_back(active[i]);
      continue;
    }
    if (i != 0) throw std::runtime_error("the free flyer (nq = 7) must be the first active joint");
    if (active[i].idx_q < 0 || active[i].idx_q + 7 > p.model.nq || active[i].idx_v < 0 || active[i].idx_v + 6 > p.model.nv)
      throw std::runtime_error("the free flyer's idx_q / idx_v are out of the model's range");
    p.floating = true;
    p.base_q = active[i].idx_q;
    p.base_v = active[i].idx_v;
  }
  if (lower.size() != p.n() || upper.size() != lower.size())
    throw std::runtime_error("limits must have one value per active coordinate (six for a free flyer)");
  p.data = pinocchio::Data(p.model);
  p.cdata = pinocchio::Data(p.model);
  p.geom_data.reset(new pinocchio::GeometryData(p.geom));
  p.manager.reset(new Manager(&p.model, &p.geom, p.geom_data.get()));
  p.full = reference;
  p.lower = lower;
  p.upper = upper;
  p.margin = margin;
  p.resolution = resolution;
  p.Ja.setZero(6, p.model.nv);
  p.Jb.setZero(6, p.model.nv);
  p.tolerance.resize(0);
}

Space::~Space() = default;

void Space::add_pose(int frame, const Eigen::Matrix3d& rotation, const std::vector<int>& position_axes,
                     const std::vector<int>& orientation_axes, const Vec& y) {
  Impl& p = *impl_;
  if (frame < 0 || frame >= static_cast<int>(p.model.nframes)) throw std::runtime_error("pose frame id out of range");
  if (y.size() != static_cast<long>(position_axes.size())) throw std::runtime_error("pose y must give each position axis");
  Term t{POSE_TERM, static_cast<pinocchio::FrameIndex>(frame), 0, rotation, position_axes, orientation_axes, y,
         Eigen::Vector3d::Zero()};
  p.add(t);
}

void Space::add_chain(int frame_a, int frame_b, const Eigen::Matrix3d& rotation, const Eigen::Vector3d& offset) {
  Impl& p = *impl_;
  const int nf = static_cast<int>(p.model.nframes);
  if (frame_a < 0 || frame_b < 0 || frame_a >= nf || frame_b >= nf) throw std::runtime_error("chain frame id out of range");
  Term t{CHAIN_TERM, static_cast<pinocchio::FrameIndex>(frame_a), static_cast<pinocchio::FrameIndex>(frame_b), rotation, {}, {},
         Vec(), offset};
  p.add(t);
}

void Space::add_sphere(int frame, const Eigen::Vector3d& center, double radius) {
  Impl& p = *impl_;
  if (frame < 0 || frame >= static_cast<int>(p.model.nframes)) throw std::runtime_error("sphere frame id out of range");
  if (!(radius > 0)) throw std::runtime_error("sphere radius must be positive");
  Term t{SPHERE_TERM, static_cast<pinocchio::FrameIndex>(frame), 0, Eigen::Matrix3d::Identity(), {}, {}, Vec::Constant(1, radius),
         center};
  p.add(t);
}

// ---------------------------------------------------------------- Whole-body terms
void Space::add_orientation(int frame, const Eigen::Vector3d& axis, const Eigen::Matrix<double, 2, 3>& basis) {
  Impl& p = *impl_;
  if (frame < 0 || frame >= static_cast<int>(p.model.nframes)) throw std::runtime_error("orientation frame id out of range");
  Term t{ORIENTATION_TERM, static_cast<pinocchio::FrameIndex>(frame), 0, Eigen::Matrix3d::Identity(), {}, {}, Vec(),
         Eigen::Vector3d::Zero()};
  t.axis = axis;
  t.basis = basis;
  p.add(t);
}

void Space::add_linear(const RowMat& A, const Vec& y) {
  Impl& p = *impl_;
  if (A.cols() != p.n() || A.rows() != y.size() || A.rows() == 0)
    throw std::runtime_error("linear terms need A (r, n) over the active coordinates and y (r,)");
  Term t{LINEAR_TERM, 0, 0, Eigen::Matrix3d::Identity(), {}, {}, y, Eigen::Vector3d::Zero()};
  t.A = A;
  p.add(t);
}

void Space::add_expression(Expression expression) {
  Impl& p = *impl_;
  for (int f : expression.frames())
    if (f >= static_cast<int>(p.model.nframes)) throw std::runtime_error("expression frame id out of range");
  Term t{EXPRESSION_TERM, 0, 0, Eigen::Matrix3d::Identity(), {}, {}, Vec(), Eigen::Vector3d::Zero()};
  t.compiled = std::make_shared<Compiled>(std::move(expression));
  if (t.compiled->leaves.com_jacobian.cols() != p.n()) throw std::runtime_error("the expression is for another n");
  p.add(t);
}

void Space::add_com_polygon(const RowMat& normals, const Vec& bounds) {
  Impl& p = *impl_;
  if (normals.cols() != 2 || normals.rows() != bounds.size() || normals.rows() < 3)
    throw std::runtime_error("a CoM polygon needs normals (H, 2) and bounds (H,), H >= 3");
  Inequality c{COM_POLYGON};
  c.normals = normals;
  c.bounds = bounds;
  p.g += c.rows();
  p.com_needed = true;
  p.inequalities.push_back(c);
  p.rates_stale = true;
}

void Space::add_hemisphere(int frame, const Eigen::Vector3d& axis, const Eigen::Vector3d& direction) {
  Impl& p = *impl_;
  if (frame < 0 || frame >= static_cast<int>(p.model.nframes)) throw std::runtime_error("hemisphere frame id out of range");
  Inequality c{HEMISPHERE};
  c.frame = static_cast<pinocchio::FrameIndex>(frame);
  c.axis = axis;
  c.direction = direction;
  p.g += c.rows();
  p.inequalities.push_back(c);
  p.rates_stale = true;
}

void Space::add_expression_inequality(Expression expression) {
  Impl& p = *impl_;
  for (int f : expression.frames())
    if (f >= static_cast<int>(p.model.nframes)) throw std::runtime_error("expression frame id out of range");
  Inequality c{EXPRESSION_INEQUALITY};
  c.compiled = std::make_shared<Compiled>(std::move(expression));
  if (c.compiled->leaves.com_jacobian.cols() != p.n()) throw std::runtime_error("the expression is for another n");
  p.g += c.rows();
  p.inequalities.push_back(c);
  p.rates_stale = true;
}

int Space::g() const { return impl_->g; }

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

void Space::set_tolerance(const Vec& tolerance) {
  if (tolerance.size() != impl_->m) throw std::runtime_error("tolerance must have one value per residual component");
  if ((tolerance.array() <= 0).any()) throw std::runtime_error("tolerances must be positive");
  impl_->tolerance = tolerance;
}

void Space::set_spheres(const std::vector<int>& joint, const RowMat& center, const Vec& radius,
                        const std::vector<int>& geometry, const std::vector<std::pair<int, int>>& exact) {
  Impl& p = *impl_;
  const std::size_t S = joint.size();
  if (center.rows() != static_cast<long>(S) || center.cols() != 3 || radius.size() != static_cast<long>(S) ||
      geometry.size() != S)
    throw std::runtime_error("spheres need joint (S,), center (S, 3), radius (S,) and geometry (S,) of one length S");
  const int ng = static_cast<int>(p.geom.ngeoms);
  p.spheres_of.assign(ng, {});
  for (std::size_t s = 0; s < S; ++s) {
    if (joint[s] < 0 || joint[s] >= static_cast<int>(p.model.njoints))
      throw std::runtime_error("sphere joint id out of range");
    if (geometry[s] < 0 || geometry[s] >= ng) throw std::runtime_error("sphere geometry index out of range");
    if (!(radius[s] >= 0)) throw std::runtime_error("sphere radii must be >= 0");
    if (static_cast<int>(p.geom.geometryObjects[geometry[s]].parentJoint) != joint[s])
      throw std::runtime_error("a sphere's joint must be the parent joint of the geometry it covers");
    p.spheres_of[geometry[s]].push_back(static_cast<int>(s));
  }
  p.sphere_joint = joint;
  p.sphere_center = center;
  p.sphere_radius = radius;
  p.world.assign(S, Eigen::Vector3d::Zero());
  p.placed_spheres.assign(ng, false);
  p.bound_center.assign(ng, Eigen::Vector3d::Zero());
  p.bound_world.assign(ng, Eigen::Vector3d::Zero());
  p.bound_radius.assign(ng, 0.0);
  p.bound_joint.assign(ng, -1);
  for (int g = 0; g < ng; ++g) {
    if (p.spheres_of[g].empty()) continue;
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int s : p.spheres_of[g]) c += center.row(s).transpose();
    c /= static_cast<double>(p.spheres_of[g].size());
    double r = 0.0;
    for (int s : p.spheres_of[g]) r = std::max(r, (Eigen::Vector3d(center.row(s).transpose()) - c).norm() + radius[s]);
    p.bound_center[g] = c;
    p.bound_radius[g] = r;
    p.bound_joint[g] = joint[p.spheres_of[g].front()];
  }
  p.shapes.clear();
  for (const auto& g : p.geom.geometryObjects) p.shapes.push_back(shape_of(g));
  p.shape_pose.assign(ng, pinocchio::SE3::Identity());
  p.shape_placed.assign(ng, false);
  p.outer.assign(ng, nullptr);
  p.outer_ready.assign(ng, false);
  p.outer_requests.clear();
  for (std::size_t k = 0; k < p.geom.collisionPairs.size(); ++k) {
    coal::CollisionRequest request(coal::NO_REQUEST, 1);
    request.security_margin = p.geom_data->collisionRequests[k].security_margin + HULL_MARGIN;
    request.gjk_initial_guess = coal::GJKInitialGuess::CachedGuess;
    request.distance_upper_bound = 0.0;  // GJK stops once it proves the hulls farther apart than the margin
    p.outer_requests.push_back(request);
  }
  p.tests.clear();
  for (std::size_t k = 0; k < p.geom.collisionPairs.size(); ++k) {
    const int a = static_cast<int>(p.geom.collisionPairs[k].first), b = static_cast<int>(p.geom.collisionPairs[k].second);
    const bool sa = !p.spheres_of[a].empty(), sb = !p.spheres_of[b].empty();
    const bool forced = std::find(exact.begin(), exact.end(), std::make_pair(a, b)) != exact.end() ||
                        std::find(exact.begin(), exact.end(), std::make_pair(b, a)) != exact.end();
    // a primitive (box, sphere, cylinder: an obstacle, a held tray) is tested exactly against the other's
    // spheres, tighter than its own spheres would be
    if (forced) p.tests.push_back({EXACT_PAIR, a, b, k});
    else if (sa && p.shapes[b].kind != NO_SHAPE) p.tests.push_back({SPHERES_PRIMITIVE, a, b, k});
    else if (sb && p.shapes[a].kind != NO_SHAPE) p.tests.push_back({SPHERES_PRIMITIVE, b, a, k});
    else if (sa && sb) p.tests.push_back({SPHERES_SPHERES, a, b, k});
    else p.tests.push_back({EXACT_PAIR, a, b, k});
  }
  // cheapest first: primitives, then sphere pairs, exact pairs last
  std::stable_sort(p.tests.begin(), p.tests.end(), [](const PairTest& x, const PairTest& y) {
    static const int rank[3] = {1, 0, 2};  // by PairKind: spheres-primitive first, then sphere pairs, exact last
    return rank[x.kind] < rank[y.kind];
  });
  for (const auto& pair : p.geom.collisionPairs) {  // the hulls now, not in the first plan's checks
    p.outer_of(static_cast<int>(pair.first));
    p.outer_of(static_cast<int>(pair.second));
  }
  p.span_d = Vec::Zero(p.n());
  p.last_stop = -1;
  p.build_holders();
}

void Space::clear_spheres() {
  impl_->sphere_joint.clear();
  impl_->tests.clear();
}

bool Space::has_spheres() const { return !impl_->sphere_joint.empty(); }

void Space::set_sweeps(bool on) { impl_->sweeps_on = on; }
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

RowMat Space::sphere_centers(const double* q) {
  Impl& p = *impl_;
  p.place_kinematics(q);
  RowMat out(p.sphere_joint.size(), 3);
  for (int g = 0; g < static_cast<int>(p.spheres_of.size()); ++g) p.place(g);
  for (std::size_t s = 0; s < p.sphere_joint.size(); ++s) out.row(s) = p.world[s].transpose();
  return out;
}

std::string Space::sphere_report() const {
  int counts[3] = {0, 0, 0};
  for (const PairTest& t : impl_->tests) ++counts[t.kind];
  std::ostringstream out;
  out << impl_->sphere_joint.size() << " spheres; pairs: " << counts[0] << " sphere-sphere, " << counts[1]
      << " sphere-primitive, " << counts[2] << " exact";
  return out.str();
}

int Space::n() const { return impl_->n(); }
int Space::m() const { return impl_->m; }
double Space::margin() const { return impl_->margin; }
double Space::resolution() const { return impl_->resolution; }
const Vec& Space::tolerance() const { return impl_->tolerance; }

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

bool Space::within_limits(const double* q) const {
  const Impl& p = *impl_;
  for (int i = 0; i < p.n(); ++i)
    if (!(q[i] >= p.lower[i] - 1e-9 && q[i] <= p.upper[i] + 1e-9)) return false;  // NaN: outside
  return true;
}

bool Space::collision_free(const double* q) {
  Impl& p = *impl_;
  if (p.geom.collisionPairs.empty()) return true;
  if (!p.sphere_joint.empty()) {  // spheres as a per-pair broad phase: coal only for pairs whose spheres touch
    ++counts.sphere_checks;
    bool flagged = false;
    const bool hit = p.pairs_collide(q, flagged);
    if (flagged) ++counts.collision_checks;  // counted as before: states the spheres sent on to coal
    return !hit;
  }
  ++counts.collision_checks;
  return !pinocchio::computeCollisions(p.model, p.cdata, *p.manager, p.to_full(q), true);
}

bool Space::spheres_free(const double* q) {
  if (impl_->sphere_joint.empty()) return collision_free(q);
  ++counts.sphere_checks;
  return !impl_->spheres_hit(q);
}

int Space::code(const double* q, double limit, bool collision, bool exact) {
  if (!within_limits(q)) return LIMITS;
  if (!batched()) {
    bool hold;
    if (impl_->state_check(q, limit, hold) > limit) return CONSTRAINT;
    if (!hold) return INEQUALITY;
  } else {
    if (violation(q) > limit) return CONSTRAINT;
    if (!inequalities_hold(q)) return INEQUALITY;
  }
  if (impl_->p) {
    std::vector<double> G(impl_->p);
    inequalities(q, 1, G.data());
    if (*std::max_element(G.begin(), G.end()) > 0) return INEQUALITY;
  }
  if (collision && !(exact ? collision_free(q) : spheres_free(q))) return COLLISION;
  return VALID;
}

int Space::valid_prefix(const double* states, int k, bool last_is_node, bool collision) {
  const int nn = n();
  const double inner = 1.0 - impl_->margin;
  std::vector<int> batch;  // batched(): every state's verdict before collision, one callback for all
  if (batched() && k > 0) {
    std::vector<double> limit(k, inner);
    if (last_is_node) limit[k - 1] = 1.0;
    batch.resize(k);
    codes(states, k, limit.data(), false, true, batch.data());
  }
  for (int i = 0; i < k; ++i) {
    const double* q = states + static_cast<long>(i) * nn;
    const int c = batch.empty() ? code(q, (last_is_node && i == k - 1) ? 1.0 : inner, collision, true)
                  : batch[i] != VALID || !collision || collision_free(q) ? batch[i] : static_cast<int>(COLLISION);
    if (c != VALID) {
      stop = c;
      ++counts.stopped[c];
      return i;
    }
  }
  stop = VALID;
  return k;
}

Projection Space::project(double* q, double tol, int max_iters, double damping, double max_step) {
  Projection out;
  project_many(q, 1, tol, max_iters, damping, max_step, &out);
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

// ------------------------------------------------------------------ Python callbacks and batches
void Space::add_callback(int rows, Residuals residuals) {
  Impl& p = *impl_;
  if (rows < 0) throw std::runtime_error("a callback term needs rows >= 0");
  Term t{CALLBACK_TERM, 0, 0, Eigen::Matrix3d::Identity(), {}, {}, Vec(), Eigen::Vector3d::Zero()};
  t.callback = static_cast<int>(p.callbacks.size());
  t.callback_rows = rows;
  p.callbacks.push_back(std::move(residuals));
  p.add(t);
}

void Space::set_inequalities(int p, Inequalities inequalities) {
  if (p < 0) throw std::runtime_error("inequalities need p >= 0");
  impl_->p = p;
  impl_->inequality = std::move(inequalities);
  impl_->rates_stale = true;
}

int Space::p() const { return impl_->p; }
bool Space::batched() const { return impl_->batched(); }

void Space::Impl::fill_callbacks(const double* q, long B, Counters& counts, double* F, double* J) {
  const int nn = n(), mm = m;
  int offset = 0;
  std::vector<double> Fc, Jc;
  for (const Term& t : terms) {
    const int rows = t.callback_rows;
    if (t.kind == CALLBACK_TERM && B > 0 && rows > 0) {
      Fc.assign(B * rows, 0.0);
      if (J) Jc.assign(B * rows * nn, 0.0);
      ++counts.callback_calls;
      counts.callback_rows += B;
      callbacks[t.callback](q, B, Fc.data(), J ? Jc.data() : nullptr);
      for (long b = 0; b < B; ++b)  // rows [offset, offset + rows) of each configuration's F and J
        for (int r = 0; r < rows; ++r) {
          F[b * mm + offset + r] = Fc[b * rows + r];
          if (J) std::copy_n(Jc.data() + (b * rows + r) * nn, nn, J + (b * mm + offset + r) * nn);
        }
    }
    offset += t.rows();
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

void Space::codes(const double* q, long B, const double* limit, bool collision, bool exact, int* out) {
  const int nn = n(), pp = impl_->p;
  if (!batched()) {
    for (long b = 0; b < B; ++b) out[b] = code(q + b * nn, limit[b], collision, exact);
    return;
  }
  std::vector<double> v(B), G(B * pp);
  violations(q, B, v.data());
  inequalities(q, B, G.data());
  for (long b = 0; b < B; ++b) {
    const double* x = q + b * nn;
    if (!within_limits(x)) out[b] = LIMITS;
    else if (v[b] > limit[b]) out[b] = CONSTRAINT;
    else if (!inequalities_hold(x)) out[b] = INEQUALITY;
    else if (pp && *std::max_element(G.begin() + b * pp, G.begin() + (b + 1) * pp) > 0) out[b] = INEQUALITY;
    else if (collision && !(exact ? collision_free(x) : spheres_free(x))) out[b] = COLLISION;
    else out[b] = VALID;
  }
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
