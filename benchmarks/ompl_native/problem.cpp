// Our pose constraint and validity checker with pinocchio + coal (see problem.hpp).
//
// The robot model and the collision model (robot geometries, scene obstacles and the exact
// collision pairs manifoldgen's CollisionChecker checks: SRDF-pruned or sampled matrix, scene
// pairs) come from pinocchio's own binary serialization, written by the Python side from the
// very objects it plans with; the JSON gives the rest (active joints, locked reference, limits,
// constraint terms, query, settings).
#include "problem.hpp"

#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/collision/broadphase.hpp>
#include <pinocchio/collision/broadphase-manager.hpp>
#include <pinocchio/serialization.hpp>
#include <pinocchio/spatial.hpp>

#include <coal/broadphase/broadphase_dynamic_AABB_tree.h>

#include <boost/json.hpp>

#include <fstream>
#include <sstream>
#include <stdexcept>

namespace mgnative {

namespace json = boost::json;
using Manager = pinocchio::BroadPhaseManagerTpl<coal::DynamicAABBTreeCollisionManager>;

namespace {

Eigen::VectorXd vector_of(const json::value& v) {
  const auto& a = v.as_array();
  Eigen::VectorXd out(a.size());
  for (std::size_t i = 0; i < a.size(); ++i) out[i] = a[i].to_number<double>();
  return out;
}

std::vector<int> ints_of(const json::value& v) {
  std::vector<int> out;
  for (const auto& x : v.as_array()) out.push_back(static_cast<int>(x.to_number<long>()));
  return out;
}

// One pose term: F = [p(q)[position_axes] - y ; log3(R_target^T R(q))[orientation_axes]].
struct PoseTerm {
  pinocchio::FrameIndex frame;
  Eigen::Matrix3d rotation;
  std::vector<int> position_axes, orientation_axes;
  Eigen::VectorXd y;
  int rows() const { return static_cast<int>(position_axes.size() + orientation_axes.size()); }
};

// An active coordinate: where it sits in pinocchio's q and v (nq = 2: a continuous joint, cos/sin).
struct Active {
  int idx_q, idx_v, nq;
};

}  // namespace

struct Problem::Impl {
  pinocchio::Model model;
  pinocchio::Data data;
  pinocchio::GeometryModel geom;
  std::unique_ptr<pinocchio::GeometryData> geom_data;
  std::unique_ptr<Manager> manager;
  std::vector<Active> active;
  std::vector<PoseTerm> terms;
  Eigen::VectorXd reference, full, lower, upper, start, goal, tolerance;
  Eigen::Matrix<double, 6, Eigen::Dynamic> frame_jacobian;
  Settings settings;
  int m = 0;

  // The full pinocchio configuration of active coordinates q (n,), locked joints at the reference.
  const Eigen::VectorXd& to_full(const Eigen::Ref<const Eigen::VectorXd>& q) {
    for (std::size_t i = 0; i < active.size(); ++i) {
      const Active& a = active[i];
      if (a.nq == 2) {
        full[a.idx_q] = std::cos(q[i]);
        full[a.idx_q + 1] = std::sin(q[i]);
      } else {
        full[a.idx_q] = q[i];
      }
    }
    return full;
  }
};

Problem::Problem(const std::string& json_path) : impl_(new Impl) {
  std::ifstream file(json_path);
  if (!file) throw std::runtime_error("cannot read problem file " + json_path);
  std::stringstream text;
  text << file.rdbuf();
  json::value doc;
  try {
    doc = json::parse(text.str());
  } catch (const std::exception& e) {
    throw std::runtime_error(json_path + " is not JSON: " + e.what());
  }
  const auto& o = doc.as_object();
  Impl& p = *impl_;
  p.model.loadFromBinary(std::string(o.at("model_file").as_string()));
  p.geom.loadFromBinary(std::string(o.at("geometry_file").as_string()));
  p.data = pinocchio::Data(p.model);
  p.geom_data.reset(new pinocchio::GeometryData(p.geom));
  p.manager.reset(new Manager(&p.model, &p.geom, p.geom_data.get()));
  p.reference = vector_of(o.at("reference"));
  if (p.reference.size() != p.model.nq) throw std::runtime_error("reference has the wrong size for the model");
  p.full = p.reference;
  for (const auto& a : o.at("active").as_array()) {
    const auto& ao = a.as_object();
    p.active.push_back({static_cast<int>(ao.at("idx_q").to_number<long>()),
                        static_cast<int>(ao.at("idx_v").to_number<long>()),
                        static_cast<int>(ao.at("nq").to_number<long>())});
  }
  p.lower = vector_of(o.at("lower"));
  p.upper = vector_of(o.at("upper"));
  p.start = vector_of(o.at("start"));
  p.goal = vector_of(o.at("goal"));
  const auto& c = o.at("constraint").as_object();
  p.tolerance = vector_of(c.at("tolerance"));
  for (const auto& t : c.at("terms").as_array()) {
    const auto& to = t.as_object();
    if (to.at("type").as_string() != "pose")
      throw std::runtime_error("only pose constraint terms are supported natively");
    PoseTerm term;
    term.frame = static_cast<pinocchio::FrameIndex>(to.at("frame_id").to_number<long>());
    Eigen::VectorXd r = vector_of(to.at("rotation"));  // row-major 3x3
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) term.rotation(i, j) = r[3 * i + j];
    term.position_axes = ints_of(to.at("position_axes"));
    term.orientation_axes = ints_of(to.at("orientation_axes"));
    term.y = vector_of(to.at("y"));
    p.m += term.rows();
    p.terms.push_back(term);
  }
  if (p.tolerance.size() != p.m) throw std::runtime_error("constraint tolerance has the wrong size");
  p.frame_jacobian.setZero(6, p.model.nv);
  const auto& s = o.at("settings").as_object();
  p.settings.space = std::string(s.at("space").as_string());
  p.settings.delta = s.at("delta").to_number<double>();
  p.settings.lambda = s.at("lambda").to_number<double>();
  p.settings.range = s.at("range").to_number<double>();
  p.settings.tolerance = s.at("tolerance").to_number<double>();
  p.settings.max_iterations = static_cast<int>(s.at("max_iterations").to_number<long>());
  p.settings.time_limit = s.at("time_limit").to_number<double>();
  p.settings.seed = static_cast<unsigned long>(s.at("seed").to_number<long>());
}

Problem::~Problem() = default;

int Problem::n() const { return static_cast<int>(impl_->active.size()); }
int Problem::m() const { return impl_->m; }
const Settings& Problem::settings() const { return impl_->settings; }
const Eigen::VectorXd& Problem::lower() const { return impl_->lower; }
const Eigen::VectorXd& Problem::upper() const { return impl_->upper; }
const Eigen::VectorXd& Problem::start() const { return impl_->start; }
const Eigen::VectorXd& Problem::goal() const { return impl_->goal; }
const Eigen::VectorXd& Problem::tolerance() const { return impl_->tolerance; }

void Problem::residual(const Eigen::Ref<const Eigen::VectorXd>& q, Eigen::Ref<Eigen::VectorXd> out) {
  Impl& p = *impl_;
  ++counts.fk;
  pinocchio::forwardKinematics(p.model, p.data, p.to_full(q));
  int row = 0;
  for (const PoseTerm& t : p.terms) {
    const pinocchio::SE3& oMf = pinocchio::updateFramePlacement(p.model, p.data, t.frame);
    for (std::size_t k = 0; k < t.position_axes.size(); ++k) out[row++] = oMf.translation()[t.position_axes[k]] - t.y[k];
    const Eigen::Vector3d err = pinocchio::log3(Eigen::Matrix3d(t.rotation.transpose() * oMf.rotation()));
    for (int a : t.orientation_axes) out[row++] = err[a];
  }
}

void Problem::jacobian(const Eigen::Ref<const Eigen::VectorXd>& q, Eigen::Ref<Eigen::MatrixXd> out) {
  Impl& p = *impl_;
  ++counts.fk;
  ++counts.jacobians;
  pinocchio::computeJointJacobians(p.model, p.data, p.to_full(q));  // also the joint placements
  int row = 0;
  for (const PoseTerm& t : p.terms) {
    const pinocchio::SE3& oMf = pinocchio::updateFramePlacement(p.model, p.data, t.frame);
    p.frame_jacobian.setZero();
    pinocchio::getFrameJacobian(p.model, p.data, t.frame, pinocchio::LOCAL_WORLD_ALIGNED, p.frame_jacobian);
    double theta;
    const Eigen::Matrix3d R = oMf.rotation();
    const Eigen::Vector3d err = pinocchio::log3(Eigen::Matrix3d(t.rotation.transpose() * R), theta);
    Eigen::Matrix3d Jlog;
    pinocchio::Jlog3(theta, err, Jlog);
    // d log3(Rt^T R) = Jlog3 R^T omega_world
    const Eigen::Matrix<double, 3, Eigen::Dynamic> J_rot = Jlog * R.transpose() * p.frame_jacobian.bottomRows<3>();
    for (int a : t.position_axes) {
      for (std::size_t i = 0; i < p.active.size(); ++i) out(row, i) = p.frame_jacobian(a, p.active[i].idx_v);
      ++row;
    }
    for (int a : t.orientation_axes) {
      for (std::size_t i = 0; i < p.active.size(); ++i) out(row, i) = J_rot(a, p.active[i].idx_v);
      ++row;
    }
  }
}

bool Problem::within_limits(const Eigen::Ref<const Eigen::VectorXd>& q) const {
  const double margin = 1e-9;  // Robot.within_limits
  return ((q.array() >= impl_->lower.array() - margin) && (q.array() <= impl_->upper.array() + margin)).all();
}

bool Problem::collision_free(const Eigen::Ref<const Eigen::VectorXd>& q) {
  Impl& p = *impl_;
  ++counts.collision_checks;
  return !pinocchio::computeCollisions(p.model, p.data, *p.manager, p.to_full(q), true);
}

}  // namespace mgnative
