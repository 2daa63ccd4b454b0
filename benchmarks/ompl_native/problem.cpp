// Our constraint and validity checker (see problem.hpp): the compiled core's constrained space
// (native/src/space.cpp and its parts, the very code manifoldgen's own planner uses), built from a problem file.
//
// The robot model and the collision model (robot geometries, scene obstacles, a held object and the
// exact collision pairs manifoldgen's CollisionChecker checks: SRDF-pruned or sampled matrix, scene
// pairs) come from pinocchio's own binary serialization, written by the Python side from the very
// objects it plans with; the JSON gives the rest (active joints, locked reference, limits, the
// constraint terms of manifoldgen.core_terms.constraint_terms, query, settings).
#include "problem.hpp"

#include "core.hpp"

#include <boost/json.hpp>

#include <fstream>
#include <sstream>
#include <stdexcept>

namespace mgnative {

namespace json = boost::json;

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

mgcore::RowMat rows_of(const json::value& v) {  // a list of equal-length rows
  const auto& a = v.as_array();
  const Eigen::Index cols = a.empty() ? 0 : static_cast<Eigen::Index>(a[0].as_array().size());
  mgcore::RowMat out(static_cast<Eigen::Index>(a.size()), cols);
  for (std::size_t i = 0; i < a.size(); ++i) out.row(i) = vector_of(a[i]).transpose();
  return out;
}

// A compiled Python constraint (manifoldgen.core_terms.constraint_terms: code [[Op value, a, b]], constants, frames,
// outputs), as the core's binding builds it.
mgcore::Expression expression_of(const json::object& to, int n) {
  std::vector<mgcore::Instruction> code;
  for (const auto& instruction : to.at("code").as_array()) {
    const std::vector<int> oab = ints_of(instruction);
    code.push_back({static_cast<mgcore::Op>(oab.at(0)), oab.at(1), oab.at(2)});
  }
  std::vector<double> constants;
  for (const auto& c : to.at("constants").as_array()) constants.push_back(c.to_number<double>());
  return mgcore::Expression(std::move(code), std::move(constants), ints_of(to.at("frames")), ints_of(to.at("outputs")),
                            n);
}

// A constraint term's fields from its JSON object (Space::add_term).
struct JsonFields final : mgcore::TermFields {
  const json::object& fields;
  explicit JsonFields(const json::object& fields) : fields(fields) {}
  const json::value& at(const char* name) const {
    if (!fields.contains(name))
      throw std::runtime_error(std::string("constraint term lacks its field '") + name + "'");
    return fields.at(name);
  }
  int integer(const char* name) const override { return static_cast<int>(at(name).to_number<long>()); }
  double number(const char* name) const override { return at(name).to_number<double>(); }
  std::vector<int> ints(const char* name) const override { return ints_of(at(name)); }
  Eigen::VectorXd vector(const char* name) const override { return vector_of(at(name)); }
  mgcore::RowMat rows(const char* name) const override { return rows_of(at(name)); }
};

}  // namespace

struct Problem::Impl {
  std::unique_ptr<mgcore::Space> space;
  Eigen::VectorXd lower, upper, start, goal, tolerance;
  Eigen::VectorXd F;  // (m,) the residual beside a Jacobian
  mgcore::RowMat J;   // (m, n) row-major, as the core writes it
  Settings settings;
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
  std::vector<mgcore::Active> active;
  for (const auto& a : o.at("active").as_array()) {
    const auto& ao = a.as_object();
    active.push_back({static_cast<int>(ao.at("idx_q").to_number<long>()),
                      static_cast<int>(ao.at("idx_v").to_number<long>()),
                      static_cast<int>(ao.at("nq").to_number<long>())});
  }
  p.lower = vector_of(o.at("lower"));
  p.upper = vector_of(o.at("upper"));
  p.start = vector_of(o.at("start"));
  p.goal = vector_of(o.at("goal"));
  // margin and resolution are the core's planning rules; OMPL's tolerance and steps are its own (settings)
  p.space.reset(new mgcore::Space(std::string(o.at("model_file").as_string()),
                                  std::string(o.at("geometry_file").as_string()), vector_of(o.at("reference")),
                                  active, p.lower, p.upper, 0.0, 0.005));
  const auto& c = o.at("constraint").as_object();
  for (const auto& t : c.at("terms").as_array()) {
    const auto& to = t.as_object();
    const std::string kind(to.at("type").as_string());
    if (kind == "expression") {
      p.space->add_expression(expression_of(to, p.space->n()));
    } else if (kind == "expression_inequality") {
      p.space->add_expression_inequality(expression_of(to, p.space->n()));
    } else {
      p.space->add_term(kind, JsonFields(to));
    }
  }
  p.tolerance = vector_of(c.at("tolerance"));
  p.space->set_tolerance(p.tolerance);
  if (o.contains("spheres")) {  // the core's sphere broad phase, as our planner gets it (--set spheres=true)
    const auto& sp = o.at("spheres").as_object();
    std::vector<std::pair<int, int>> exact;
    for (const auto& pair : sp.at("exact").as_array()) {
      const std::vector<int> ab = ints_of(pair);
      exact.emplace_back(ab.at(0), ab.at(1));
    }
    p.space->set_spheres(ints_of(sp.at("joint")), rows_of(sp.at("center")), vector_of(sp.at("radius")),
                         ints_of(sp.at("geometry")), exact);
  }
  p.space->prepare();  // what its first certified check would build, built before "ready" as ours is
  p.J.resize(p.space->m(), p.space->n());
  const auto& s = o.at("settings").as_object();
  p.settings.space = std::string(s.at("space").as_string());
  p.settings.delta = s.at("delta").to_number<double>();
  p.settings.lambda = s.at("lambda").to_number<double>();
  p.settings.range = s.at("range").to_number<double>();
  p.settings.tolerance = s.at("tolerance").to_number<double>();
  p.settings.max_iterations = static_cast<int>(s.at("max_iterations").to_number<long>());
  p.settings.time_limit = s.at("time_limit").to_number<double>();
  p.settings.seed = static_cast<unsigned long>(s.at("seed").to_number<long>());
  if (s.contains("shortcut")) p.settings.shortcut = static_cast<int>(s.at("shortcut").to_number<long>());
  for (auto [key, value] : {std::pair{"epsilon", &p.settings.epsilon}, {"rho", &p.settings.rho},
                            {"alpha", &p.settings.alpha}, {"exploration", &p.settings.exploration}})
    if (s.contains(key)) *value = s.at(key).to_number<double>();
  if (s.contains("separated")) p.settings.separated = s.at("separated").as_bool();
}

Problem::~Problem() = default;

int Problem::n() const { return impl_->space->n(); }
int Problem::m() const { return impl_->space->m(); }
const Settings& Problem::settings() const { return impl_->settings; }
const Eigen::VectorXd& Problem::lower() const { return impl_->lower; }
const Eigen::VectorXd& Problem::upper() const { return impl_->upper; }
const Eigen::VectorXd& Problem::start() const { return impl_->start; }
const Eigen::VectorXd& Problem::goal() const { return impl_->goal; }
const Eigen::VectorXd& Problem::tolerance() const { return impl_->tolerance; }

// Eigen::Ref<const VectorXd> and Ref<VectorXd> are contiguous (inner stride 1): the core reads and writes them in place.
void Problem::residual(const Eigen::Ref<const Eigen::VectorXd>& q, Eigen::Ref<Eigen::VectorXd> out) {
  ++counts.fk;
  impl_->space->residual(q.data(), out.data());
}

void Problem::jacobian(const Eigen::Ref<const Eigen::VectorXd>& q, Eigen::Ref<Eigen::MatrixXd> out) {
  ++counts.fk;
  ++counts.jacobians;
  impl_->F.resize(m());
  impl_->space->jacobian(q.data(), impl_->F.data(), impl_->J.data());
  out = impl_->J;  // the core writes (m, n) row-major, OMPL reads column-major
}

bool Problem::within_limits(const Eigen::Ref<const Eigen::VectorXd>& q) const {
  return impl_->space->within_limits(q.data());
}

bool Problem::inequalities_hold(const Eigen::Ref<const Eigen::VectorXd>& q) {
  ++counts.inequalities;
  return impl_->space->inequalities_hold(q.data());
}

int Problem::g() const { return impl_->space->g(); }

bool Problem::collision_free(const Eigen::Ref<const Eigen::VectorXd>& q) {
  const mgcore::Counters& c = impl_->space->counts;  // the core counts coal's checks and the sphere tests
  const long coal = c.collision_checks, spheres = c.sphere_checks;
  const bool free = impl_->space->collision_free(q.data());
  counts.collision_checks += c.collision_checks - coal;
  counts.sphere_checks += c.sphere_checks - spheres;
  return free;
}

}  // namespace mgnative
