// The constrained space in C++ (see core.hpp): manifoldgen.space.ConstrainedSpace's rule with the
// constraint terms of constraints/pose.py, rotation.py (a pose term without position axes) and
// closed_chain.py, the projection of constraints/projection.py, and a sphere-model collision test.
// Whole-body (the blocks "Whole-body terms" here and in terms.cpp): a floating base as manifoldgen.robot's six Euler
// coordinates, orientation.py's and joint_linear.py's terms, and inequalities (balance.py's CoM margin,
// orientation.py's hemisphere); balance.py's equalities are pose terms. Any other constraint (a user's) runs as a
// compiled expression (expression.cpp: its residual and inequalities traced by manifoldgen/constraints/trace.py),
// or, where it could not be traced, through Python callbacks on batches of configurations (manifoldgen/constraint_callbacks.py
// ConstraintCallback).
//
// The space's parts (space_impl.hpp declares Space::Impl): this file builds it (the constructor, the add_*
// terms, tolerances, callbacks) and answers its size accessors; terms.cpp evaluates the terms and projects;
// collision.cpp holds the collision test and the validity rule; sweeps.cpp the dense path check.
#include "space_impl.hpp"

#include <pinocchio/serialization.hpp>

#include <stdexcept>

namespace mgcore {

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

void Space::set_tolerance(const Vec& tolerance) {
  if (tolerance.size() != impl_->m) throw std::runtime_error("tolerance must have one value per residual component");
  if ((tolerance.array() <= 0).any()) throw std::runtime_error("tolerances must be positive");
  impl_->tolerance = tolerance;
}

int Space::n() const { return impl_->n(); }
int Space::m() const { return impl_->m; }
double Space::margin() const { return impl_->margin; }
double Space::resolution() const { return impl_->resolution; }
const Vec& Space::tolerance() const { return impl_->tolerance; }

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

}  // namespace mgcore
