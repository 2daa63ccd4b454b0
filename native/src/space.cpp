// The constrained space in C++ (see core.hpp): manifoldgen.space.ConstrainedSpace's rule with the built-in
// constraint terms (builtin_terms.cpp: pose, rotation as a pose, closed chain, sphere, orientation, joint_linear,
// balance's CoM margin and equalities, orientation's hemisphere), the projection of constraints/projection.py, a
// sphere-model collision test, and a floating base as manifoldgen.robot's six Euler coordinates. Any other
// constraint (a user's) runs as a compiled expression (expression.cpp: its residual and inequalities traced by
// manifoldgen/constraints/trace.py), or, where it could not be traced, through Python callbacks on batches of
// configurations (manifoldgen/constraint_callbacks.py ConstraintCallback).
//
// The space's parts (space_impl.hpp declares Space::Impl): this file builds it (the constructor, the compiled and
// callback terms, tolerances) and answers its size accessors; builtin_terms.cpp holds the built-in terms and builds
// them by name; terms.cpp evaluates the terms and projects; collision.cpp holds the collision test and the validity
// rule; sweeps.cpp the dense path check.
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

// A compiled expression's frame ids, checked against the model (its n is checked by the caller).
static void check_frames(const Space::Impl& p, const Expression& expression) {
  for (int f : expression.frames())
    if (f >= static_cast<int>(p.model.nframes)) throw std::runtime_error("expression frame id out of range");
}

void Space::add_expression(Expression expression) {
  Impl& p = *impl_;
  check_frames(p, expression);
  auto t = std::make_unique<ExpressionTerm>(std::move(expression));
  if (t->compiled.leaves.com_jacobian.cols() != p.n()) throw std::runtime_error("the expression is for another n");
  p.add(std::unique_ptr<const Term>(std::move(t)));
}

void Space::add_expression_inequality(Expression expression) {
  Impl& p = *impl_;
  check_frames(p, expression);
  auto c = std::make_unique<ExpressionInequality>(std::move(expression));
  if (c->compiled.leaves.com_jacobian.cols() != p.n()) throw std::runtime_error("the expression is for another n");
  p.add(std::unique_ptr<const Inequality>(std::move(c)));
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
  p.add(std::make_unique<const CallbackTerm>(static_cast<int>(p.callbacks.size()), rows));
  p.callbacks.push_back(std::move(residuals));
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
