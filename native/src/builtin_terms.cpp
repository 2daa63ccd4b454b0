// The built-in constraint terms, each in one place: its fields (read by name, as
// manifoldgen.core_terms.constraint_terms writes them), its rows and Jacobian rows, and its certificate for
// certified sweeps; and the table that builds them by name (Space::add_term), which the binding and the C++ OMPL
// baseline both call. A new built-in term: its struct here and its entry in BUILT_IN.
#include "space_impl.hpp"

#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>

#include <memory>
#include <stdexcept>
#include <string>
#include <type_traits>

namespace mgcore {
namespace {

using Impl = Space::Impl;

Eigen::Vector3d vector3_of(const TermFields& f, const char* field) {
  const Vec v = f.vector(field);
  if (v.size() != 3) throw std::invalid_argument(std::string("constraint term field '") + field + "' needs 3 numbers");
  return v;
}

Eigen::Matrix3d rotation_of(const TermFields& f, const char* field) {  // row-major 3 x 3
  const Vec v = f.vector(field);
  if (v.size() != 9)
    throw std::invalid_argument(std::string("constraint term field '") + field + "' needs 9 numbers (row-major 3 x 3)");
  return Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(v.data());
}

// A frame's placement, and its Jacobian in p.Ja (LOCAL_WORLD_ALIGNED; joint Jacobians done).
const pinocchio::SE3& placed_with_jacobian(Impl& p, pinocchio::FrameIndex frame) {
  const pinocchio::SE3& A = pinocchio::updateFramePlacement(p.model, p.data, frame);
  p.Ja.setZero();
  pinocchio::getFrameJacobian(p.model, p.data, frame, pinocchio::LOCAL_WORLD_ALIGNED, p.Ja);
  return A;
}

// pose: F = [p(q)[position_axes] - y ; log3(rotation^T R(q))[orientation_axes]] (constraints/pose.py; rotation.py is
// a pose without position axes). Certificate: the positions' point rates; the log3 rows LOG_RATE times the turning
// rates while the rotation error's angle a stays <= 1 rad (|d log3| <= (a/2)/sin(a/2) |omega|), guarded by one row
// (rate: turning, slack: 1 - a).
struct Pose final : Term {
  pinocchio::FrameIndex frame;
  Eigen::Matrix3d rotation;
  std::vector<int> position_axes, orientation_axes;
  Vec y;  // the conditioned positions
  Pose(const Impl& p, const TermFields& f)
      : frame(p.frame_of(f.integer("frame_id"), "pose")), rotation(rotation_of(f, "rotation")),
        position_axes(f.ints("position_axes")), orientation_axes(f.ints("orientation_axes")), y(f.vector("y")) {
    if (y.size() != static_cast<long>(position_axes.size()))
      throw std::invalid_argument("pose y must give each position axis");
    for (const auto* axes : {&position_axes, &orientation_axes})
      for (int a : *axes)
        if (a < 0 || a > 2) throw std::invalid_argument("pose axes must be 0, 1 or 2 (x, y, z)");
  }
  int rows() const override { return static_cast<int>(position_axes.size() + orientation_axes.size()); }
  void values(Impl& p, const double*, double* F) const override {
    const pinocchio::SE3& A = pinocchio::updateFramePlacement(p.model, p.data, frame);
    int row = 0;
    for (std::size_t k = 0; k < position_axes.size(); ++k) F[row++] = A.translation()[position_axes[k]] - y[k];
    const Eigen::Vector3d err = pinocchio::log3(Eigen::Matrix3d(rotation.transpose() * A.rotation()));
    for (int a : orientation_axes) F[row++] = err[a];
  }
  void jacobian(Impl& p, const double*, double* F, double* J) const override {
    const pinocchio::SE3& A = placed_with_jacobian(p, frame);
    const long nn = p.n();
    double theta;
    const Eigen::Vector3d err = pinocchio::log3(Eigen::Matrix3d(rotation.transpose() * A.rotation()), theta);
    Eigen::Matrix3d Jlog;
    pinocchio::Jlog3(theta, err, Jlog);
    const Eigen::Matrix<double, 3, Eigen::Dynamic> Jrot = Jlog * A.rotation().transpose() * p.Ja.bottomRows<3>();
    int row = 0;
    for (std::size_t k = 0; k < position_axes.size(); ++k) {
      F[row] = A.translation()[position_axes[k]] - y[k];
      p.put_row(J + row++ * nn, p.Ja.row(position_axes[k]));
    }
    for (int a : orientation_axes) {
      F[row] = err[a];
      p.put_row(J + row++ * nn, Jrot.row(a));
    }
  }
  bool rates(const Impl& p, std::vector<Vec>& rows, std::vector<Vec>& guards) const override {
    for (std::size_t k = 0; k < position_axes.size(); ++k) rows.push_back(p.frame_rates(frame, false));
    for (std::size_t k = 0; k < orientation_axes.size(); ++k)
      rows.push_back(Impl::LOG_RATE * p.frame_rates(frame, true));
    if (!orientation_axes.empty()) guards.push_back(p.frame_rates(frame, true));
    return true;
  }
  int guard_slack(const Impl& p, double* slack) const override {
    const Eigen::Matrix3d R = rotation.transpose() * p.data.oMf[frame].rotation();
    slack[0] = 1.0 - std::acos(std::clamp((R.trace() - 1.0) / 2.0, -1.0, 1.0));
    return 1;
  }
};

// closed chain: F = [Ra^T (pb - pa) - offset ; log3(rotation^T Ra^T Rb)] (constraints/closed_chain.py). No
// certificate.
struct Chain final : Term {
  pinocchio::FrameIndex frame_a, frame_b;
  Eigen::Matrix3d rotation;
  Eigen::Vector3d offset;  // d * axis
  Chain(const Impl& p, const TermFields& f)
      : frame_a(p.frame_of(f.integer("frame_a_id"), "chain")), frame_b(p.frame_of(f.integer("frame_b_id"), "chain")),
        rotation(rotation_of(f, "rotation")), offset(vector3_of(f, "offset")) {}
  int rows() const override { return 6; }
  void values(Impl& p, const double*, double* F) const override {
    const pinocchio::SE3& A = pinocchio::updateFramePlacement(p.model, p.data, frame_a);
    const pinocchio::SE3& B = pinocchio::updateFramePlacement(p.model, p.data, frame_b);
    const Eigen::Vector3d rel = A.rotation().transpose() * (B.translation() - A.translation()) - offset;
    const Eigen::Vector3d err =
        pinocchio::log3(Eigen::Matrix3d(rotation.transpose() * A.rotation().transpose() * B.rotation()));
    for (int i = 0; i < 3; ++i) F[i] = rel[i];
    for (int i = 0; i < 3; ++i) F[3 + i] = err[i];
  }
  void jacobian(Impl& p, const double*, double* F, double* J) const override {
    const pinocchio::SE3& A = placed_with_jacobian(p, frame_a);
    const pinocchio::SE3& B = pinocchio::updateFramePlacement(p.model, p.data, frame_b);
    p.Jb.setZero();
    pinocchio::getFrameJacobian(p.model, p.data, frame_b, pinocchio::LOCAL_WORLD_ALIGNED, p.Jb);
    const long nn = p.n();
    const Eigen::Matrix3d RaT = A.rotation().transpose();
    const Eigen::Vector3d r = B.translation() - A.translation();
    const Eigen::Vector3d rel = RaT * r - offset;
    double theta;
    const Eigen::Vector3d err = pinocchio::log3(Eigen::Matrix3d(rotation.transpose() * RaT * B.rotation()), theta);
    Eigen::Matrix3d Jlog;
    pinocchio::Jlog3(theta, err, Jlog);
    const Eigen::Matrix<double, 3, Eigen::Dynamic> Jpos =
        RaT * (p.Jb.topRows<3>() - p.Ja.topRows<3>() + pinocchio::skew(r) * p.Ja.bottomRows<3>());
    const Eigen::Matrix<double, 3, Eigen::Dynamic> Jrot =
        Jlog * B.rotation().transpose() * (p.Jb.bottomRows<3>() - p.Ja.bottomRows<3>());
    for (int i = 0; i < 3; ++i) {
      F[i] = rel[i];
      p.put_row(J + i * nn, Jpos.row(i));
    }
    for (int i = 0; i < 3; ++i) {
      F[3 + i] = err[i];
      p.put_row(J + (3 + i) * nn, Jrot.row(i));
    }
  }
};

// sphere: F = |p(q) - center| - radius (constraints/sphere.py). Certificate: the point's rates.
struct Sphere final : Term {
  pinocchio::FrameIndex frame;
  Eigen::Vector3d center;
  double radius;
  Sphere(const Impl& p, const TermFields& f)
      : frame(p.frame_of(f.integer("frame_id"), "sphere")), center(vector3_of(f, "center")),
        radius(f.number("radius")) {
    if (!(radius > 0)) throw std::invalid_argument("sphere radius must be positive");
  }
  int rows() const override { return 1; }
  void values(Impl& p, const double*, double* F) const override {
    F[0] = (pinocchio::updateFramePlacement(p.model, p.data, frame).translation() - center).norm() - radius;
  }
  void jacobian(Impl& p, const double*, double* F, double* J) const override {
    const Eigen::Vector3d d = placed_with_jacobian(p, frame).translation() - center;
    const double r = d.norm();
    F[0] = r - radius;
    p.put_row(J, (d / std::max(r, 1e-12)).transpose() * p.Ja.topRows<3>());
  }
  bool rates(const Impl& p, std::vector<Vec>& rows, std::vector<Vec>&) const override {
    rows.push_back(p.frame_rates(frame, false));
    return true;
  }
};

// orientation: F = basis (2, 3) . R(q) axis (constraints/orientation.py). Certificate: |basis_r| |axis| times the
// turning rates.
struct Orientation final : Term {
  pinocchio::FrameIndex frame;
  Eigen::Vector3d axis;  // the frame's axis
  Eigen::Matrix<double, 2, 3> basis;  // e1, e2
  Orientation(const Impl& p, const TermFields& f)
      : frame(p.frame_of(f.integer("frame_id"), "orientation")), axis(vector3_of(f, "axis")) {
    const RowMat b = f.rows("basis");
    if (b.rows() != 2 || b.cols() != 3) throw std::invalid_argument("orientation needs basis (2, 3)");
    basis = b;
  }
  int rows() const override { return 2; }
  void values(Impl& p, const double*, double* F) const override {
    const pinocchio::SE3& A = pinocchio::updateFramePlacement(p.model, p.data, frame);
    Eigen::Map<Eigen::Vector2d>{F} = basis * (A.rotation() * axis);
  }
  void jacobian(Impl& p, const double*, double* F, double* J) const override {
    const pinocchio::SE3& A = placed_with_jacobian(p, frame);
    const long nn = p.n();
    const Eigen::Vector3d pointing = A.rotation() * axis;
    Eigen::Map<Eigen::Vector2d>{F} = basis * pointing;
    // d(R axis) = omega x (R axis) = -hat(R axis) omega
    const Eigen::Matrix<double, 2, Eigen::Dynamic> rows = -(basis * pinocchio::skew(pointing)) * p.Ja.bottomRows<3>();
    for (int r = 0; r < 2; ++r) p.put_row(J + r * nn, rows.row(r));
  }
  bool rates(const Impl& p, std::vector<Vec>& rows, std::vector<Vec>&) const override {
    for (int k = 0; k < 2; ++k) rows.push_back(basis.row(k).norm() * axis.norm() * p.frame_rates(frame, true));
    return true;
  }
};

// linear: F = A (r, n) q - y over the active coordinates (constraints/joint_linear.py). Certificate: |A_r|.
struct Linear final : Term {
  RowMat A;
  Vec y;
  Linear(const Impl& p, const TermFields& f) : A(f.rows("A")), y(f.vector("y")) {
    if (A.cols() != p.n() || A.rows() != y.size() || A.rows() == 0)
      throw std::invalid_argument("linear terms need A (r, n) over the active coordinates and y (r,)");
  }
  int rows() const override { return static_cast<int>(A.rows()); }
  void values(Impl& p, const double* q, double* F) const override {
    Eigen::Map<Vec>(F, A.rows()) = A * Eigen::Map<const Vec>(q, p.n()) - y;
  }
  void jacobian(Impl& p, const double* q, double* F, double* J) const override {
    const int nn = p.n();
    Eigen::Map<Vec>(F, A.rows()) = A * Eigen::Map<const Vec>(q, nn) - y;
    Eigen::Map<RowMat>(J, A.rows(), nn) = A;
  }
  bool rates(const Impl&, std::vector<Vec>& rows, std::vector<Vec>&) const override {
    for (int k = 0; k < A.rows(); ++k) rows.push_back(A.row(k).cwiseAbs().transpose());
    return true;
  }
};

// com polygon: G = normals (H, 2) . com(q)[x, y] - bounds (H,) (constraints/balance.py's CoM margin). Certificate:
// |normal_h| times the centre of mass's rates.
struct ComPolygon final : Inequality {
  RowMat normals;  // (H, 2)
  Vec bounds;      // (H,)
  ComPolygon(const Impl&, const TermFields& f) : normals(f.rows("normals")), bounds(f.vector("bounds")) {
    if (normals.cols() != 2 || normals.rows() != bounds.size() || normals.rows() < 3)
      throw std::invalid_argument("a CoM polygon needs normals (H, 2) and bounds (H,), H >= 3");
  }
  int rows() const override { return static_cast<int>(normals.rows()); }
  bool needs_com() const override { return true; }
  void values(Impl& p, const double*, double* G) const override {
    const Eigen::Vector2d com = p.data.com[0].head<2>();
    Eigen::Map<Vec>(G, normals.rows()) = normals * com - bounds;
  }
  bool rates(const Impl& p, std::vector<Vec>& rows, std::vector<Vec>&) const override {
    const Vec com = p.com_rates();
    for (int h = 0; h < normals.rows(); ++h) rows.push_back(normals.row(h).norm() * com);
    return true;
  }
};

// hemisphere: G = -direction . R(q) axis (constraints/orientation.py's inequality). Certificate: |direction| |axis|
// times the turning rates.
struct Hemisphere final : Inequality {
  pinocchio::FrameIndex frame;
  Eigen::Vector3d axis, direction;
  Hemisphere(const Impl& p, const TermFields& f)
      : frame(p.frame_of(f.integer("frame_id"), "hemisphere")), axis(vector3_of(f, "axis")),
        direction(vector3_of(f, "direction")) {}
  int rows() const override { return 1; }
  void values(Impl& p, const double*, double* G) const override {
    G[0] = -direction.dot(pinocchio::updateFramePlacement(p.model, p.data, frame).rotation() * axis);
  }
  bool rates(const Impl& p, std::vector<Vec>& rows, std::vector<Vec>&) const override {
    rows.push_back(direction.norm() * axis.norm() * p.frame_rates(frame, true));
    return true;
  }
};

template <class T>
void build(Impl& p, const TermFields& f) {
  using Kind = std::conditional_t<std::is_base_of_v<Term, T>, Term, Inequality>;
  p.add(std::unique_ptr<const Kind>(std::make_unique<T>(p, f)));
}

// The table: a term's type name and its builder.
const std::vector<std::pair<std::string, void (*)(Impl&, const TermFields&)>> BUILT_IN = {
    {"pose", build<Pose>},
    {"chain", build<Chain>},
    {"sphere", build<Sphere>},
    {"orientation", build<Orientation>},
    {"linear", build<Linear>},
    {"com_polygon", build<ComPolygon>},
    {"hemisphere", build<Hemisphere>},
};

}  // namespace

void Space::add_term(const std::string& kind, const TermFields& fields) {
  for (const auto& [name, builder] : BUILT_IN)
    if (name == kind) return builder(*impl_, fields);
  std::string known;
  for (const auto& entry : BUILT_IN) known += (known.empty() ? "" : ", ") + entry.first;
  throw std::invalid_argument("unknown constraint term type '" + kind + "' (built in: " + known + ")");
}

std::vector<std::string> Space::built_in_terms() {
  std::vector<std::string> names;
  for (const auto& entry : BUILT_IN) names.push_back(entry.first);
  return names;
}

}  // namespace mgcore
