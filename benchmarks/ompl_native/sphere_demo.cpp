// OMPL's sphere demo (demos/constraint/ConstrainedPlanningSphere.cpp) as a benchmark program: a point
// in R^3 on a sphere of radius r about the origin, three obstacle bands with narrow openings, from the
// south pole (0, 0, -r) to the north pole (0, 0, r), RRTConnect in OMPL's Projected, Atlas or
// TangentBundle space. OMPL only (no pinocchio, no manifoldgen); one JSON line per seed on stdout.
//
//   sphere_demo [--space atlas|projected|tangent] [--seeds FIRST:END] [--time 5] [--radius 1]
//               [--tolerance 1e-4] [--check-tolerance 0.01] [--resolution 0.005]
//
// Settings are the demo's defaults: OMPL tolerance 1e-4 on |F| = | |x| - r | (one residual: OMPL's
// norm is the absolute value), 50 Newton iterations, delta 0.05, lambda 2, atlas epsilon 0.05,
// rho 5 delta, alpha pi/8, exploration 0.75, 200 charts per extension, separated charts (Atlas), and
// RRTConnect's range rho_s for Atlas and TangentBundle, OMPL's default for Projected. The demo only
// checks the states OMPL makes (every delta along its discrete geodesics); here each exact solution,
// interpolated by OMPL, is also checked densely as manifoldgen checks its paths: states every
// `resolution` along every straight segment, each within `check-tolerance` of the sphere and outside
// the bands. A refused path does not end the run: OMPL searches again (a new tree, the atlas keeps
// its charts) within the remaining time, the retry policy of every manifoldgen benchmark method.
// --check-tolerance 0 turns the dense check off (the demo as it is).
//
// Per seed: {"space", "seed", "solved", "status", "time_s", "cpu_s", "length", "states", "attempts",
// "rejected_paths", "function_calls", "jacobian_calls", "projections", "validity_checks",
// "dense_checks", "samples", "vertices", "charts"}; times are from building the space to the final
// verdict, dense check included; counts are over the whole run.
#include "ompl_common.hpp"

#include <ompl/base/Constraint.h>
#include <ompl/base/PlannerData.h>
#include <ompl/base/spaces/RealVectorStateSpace.h>
#include <ompl/base/spaces/constraint/AtlasStateSpace.h>
#include <ompl/geometric/SimpleSetup.h>
#include <ompl/geometric/planners/rrt/RRTConnect.h>
#include <ompl/util/Console.h>
#include <ompl/util/RandomNumbers.h>

#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

namespace ob = ompl::base;
namespace og = ompl::geometric;

namespace {

using ompl_common::cpu_seconds;
using ompl_common::wall_seconds;

struct Options {
  std::string space = "atlas";
  long first = 0, end = 1;        // seeds [first, end)
  double time = 5.0;              // the demo's default time limit (s)
  double radius = 1.0;
  double tolerance = ompl::magic::CONSTRAINT_PROJECTION_TOLERANCE;  // 1e-4
  double check_tolerance = 0.01;  // manifoldgen's `sphere` task tolerance (m); 0: no dense check
  double resolution = 0.005;      // manifoldgen's dense validation spacing
};

// |x| - r and its gradient, counting the calls (OMPL's projection calls both).
class SphereConstraint : public ob::Constraint {
 public:
  SphereConstraint(double radius, double tolerance) : ob::Constraint(3, 1, tolerance), radius_(radius) {}

  void function(const Eigen::Ref<const Eigen::VectorXd>& x, Eigen::Ref<Eigen::VectorXd> out) const override {
    ++function_calls;
    out[0] = x.norm() - radius_;
  }

  void jacobian(const Eigen::Ref<const Eigen::VectorXd>& x, Eigen::Ref<Eigen::MatrixXd> out) const override {
    ++jacobian_calls;
    out = x.transpose().normalized();
  }

  bool project(Eigen::Ref<Eigen::VectorXd> x) const override {
    ++projections;
    return ob::Constraint::project(x);
  }

  mutable long function_calls = 0, jacobian_calls = 0, projections = 0;

 private:
  double radius_;
};

// The demo's obstacles: three bands in z, each open only in a strip 0.1 wide (a state on a boundary
// is free, as in the demo's strict inequalities).
bool outside_bands(const double* x) {
  if (-0.80 < x[2] && x[2] < -0.6) return -0.05 < x[1] && x[1] < 0.05 && x[0] > 0;
  if (-0.1 < x[2] && x[2] < 0.1) return -0.05 < x[0] && x[0] < 0.05 && x[1] < 0;
  if (0.6 < x[2] && x[2] < 0.80) return -0.05 < x[1] && x[1] < 0.05 && x[0] < 0;
  return true;
}

class CountingSampler : public ob::StateSampler {
 public:
  CountingSampler(const ob::StateSpace* space, ob::StateSamplerPtr inner, long& count)
      : ob::StateSampler(space), inner_(std::move(inner)), count_(count) {}
  void sampleUniform(ob::State* state) override { ++count_, inner_->sampleUniform(state); }
  void sampleUniformNear(ob::State* state, const ob::State* near, double distance) override {
    ++count_, inner_->sampleUniformNear(state, near, distance);
  }
  void sampleGaussian(ob::State* state, const ob::State* mean, double std_dev) override {
    ++count_, inner_->sampleGaussian(state, mean, std_dev);
  }

 private:
  ob::StateSamplerPtr inner_;
  long& count_;
};

// RRTConnect whose sampler counts the samples it draws (the space's own sampler, wrapped).
class CountingRRTConnect : public og::RRTConnect {
 public:
  using og::RRTConnect::RRTConnect;
  ob::PlannerStatus solve(const ob::PlannerTerminationCondition& ptc) override {
    if (!sampler_)
      sampler_ = std::make_shared<CountingSampler>(si_->getStateSpace().get(), si_->allocStateSampler(), samples);
    return og::RRTConnect::solve(ptc);
  }
  long samples = 0;
};

// manifoldgen's dense check of a path: states every `resolution` along each straight segment, each
// within `tolerance` of the sphere, inside the bounds and outside the bands; counts the states checked.
bool dense_check(const og::PathGeometric& path, const Options& o, long& checked) {
  for (std::size_t k = 0; k + 1 < path.getStateCount(); ++k) {
    const Eigen::Map<Eigen::VectorXd>& a = *path.getState(k)->as<ob::ConstrainedStateSpace::StateType>();
    const Eigen::Map<Eigen::VectorXd>& b = *path.getState(k + 1)->as<ob::ConstrainedStateSpace::StateType>();
    const int steps = std::max(1, static_cast<int>(std::ceil((b - a).norm() / o.resolution)));
    for (int i = (k == 0 ? 0 : 1); i <= steps; ++i) {
      const Eigen::Vector3d x = a + (b - a) * (static_cast<double>(i) / steps);
      ++checked;
      const bool on_sphere = std::abs(x.norm() - o.radius) <= o.check_tolerance;
      if (!on_sphere || x.cwiseAbs().maxCoeff() > 2.0 || !outside_bands(x.data())) return false;
    }
  }
  return true;
}

void run(const Options& o, long seed) {
  ompl::msg::setLogLevel(ompl::msg::LOG_NONE);  // reseeding after the first run is reported as an error
  ompl::RNG::setSeed(static_cast<std::uint_fast32_t>(seed % 2147483647L + 1));
  ompl::msg::setLogLevel(ompl::msg::LOG_WARN);
  const double cpu0 = cpu_seconds(), wall0 = wall_seconds();

  auto ambient = std::make_shared<ob::RealVectorStateSpace>(3);
  ambient->setBounds(-2, 2);
  auto constraint = std::make_shared<SphereConstraint>(o.radius, o.tolerance);
  const auto [space, si] = ompl_common::constrained_space(o.space, ambient, constraint);
  space->setup();
  space->setDelta(ompl::magic::CONSTRAINED_STATE_SPACE_DELTA);
  space->setLambda(ompl::magic::CONSTRAINED_STATE_SPACE_LAMBDA);
  std::shared_ptr<ob::AtlasStateSpace> atlas;
  if (o.space != "projected") {
    atlas = std::static_pointer_cast<ob::AtlasStateSpace>(space);
    atlas->setExploration(ompl::magic::ATLAS_STATE_SPACE_EXPLORATION);
    atlas->setEpsilon(ompl::magic::ATLAS_STATE_SPACE_EPSILON);
    atlas->setRho(ompl::magic::CONSTRAINED_STATE_SPACE_DELTA * ompl::magic::ATLAS_STATE_SPACE_RHO_MULTIPLIER);
    atlas->setAlpha(ompl::magic::ATLAS_STATE_SPACE_ALPHA);
    atlas->setMaxChartsPerExtension(ompl::magic::ATLAS_STATE_SPACE_MAX_CHARTS_PER_EXTENSION);
    if (o.space == "atlas") atlas->setSeparated(true);
    atlas->setup();
  }
  long validity_checks = 0;
  si->setStateValidityChecker([&validity_checks](const ob::State* state) {
    ++validity_checks;
    const Eigen::Map<Eigen::VectorXd>& x = *state->as<ob::ConstrainedStateSpace::StateType>();
    return outside_bands(x.data());
  });

  og::SimpleSetup setup(si);
  ob::ScopedState<> start(space), goal(space);
  start->as<ob::ConstrainedStateSpace::StateType>()->copy(Eigen::Vector3d(0, 0, -o.radius));
  goal->as<ob::ConstrainedStateSpace::StateType>()->copy(Eigen::Vector3d(0, 0, o.radius));
  if (atlas) {
    atlas->anchorChart(start.get());
    atlas->anchorChart(goal.get());
  }
  setup.setStartAndGoalStates(start, goal);
  auto planner = std::make_shared<CountingRRTConnect>(si);
  if (atlas) planner->setRange(atlas->getRho_s());
  setup.setPlanner(planner);
  setup.setup();

  long dense = 0;
  double length = 0;
  std::size_t states = 0;
  const ompl_common::Outcome run =
      ompl_common::solve_with_retries(setup, si, o.time, wall0, [&](og::PathGeometric& path) {
        length = path.length();
        states = path.getStateCount();
        return o.check_tolerance <= 0 || dense_check(path, o, dense);
      });
  const double wall = wall_seconds() - wall0, cpu = cpu_seconds() - cpu0;
  std::printf(
      "{\"space\": \"%s\", \"seed\": %ld, \"solved\": %s, \"status\": \"%s\", \"time_s\": %.6f, \"cpu_s\": %.6f, "
      "\"length\": %.6f, \"states\": %zu, \"attempts\": %d, \"rejected_paths\": %d, \"function_calls\": %ld, "
      "\"jacobian_calls\": %ld, \"projections\": %ld, \"validity_checks\": %ld, \"dense_checks\": %ld, "
      "\"samples\": %ld, \"vertices\": %ld, \"charts\": %ld, \"radius\": %g, \"tolerance\": %g, "
      "\"check_tolerance\": %g, \"resolution\": %g, \"time_limit\": %g}\n",
      o.space.c_str(), seed, run.solved ? "true" : "false", run.status.c_str(), wall, cpu,
      run.solved ? length : 0.0, run.solved ? states : 0, run.attempts, run.rejected, constraint->function_calls,
      constraint->jacobian_calls, constraint->projections, validity_checks, dense, planner->samples, run.vertices,
      atlas ? static_cast<long>(atlas->getChartCount()) : 0L, o.radius, o.tolerance, o.check_tolerance,
      o.resolution, o.time);
  std::fflush(stdout);
}

double number(const std::string& flag, const char* text) {
  try {
    std::size_t used = 0;
    const double value = std::stod(text, &used);
    if (used == std::string(text).size() && std::isfinite(value)) return value;
  } catch (const std::exception&) {
  }
  throw std::runtime_error(flag + " needs a number, got '" + text + "'");
}

Options parse(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; i += 2) {
    const std::string flag = argv[i];
    if (i + 1 >= argc) throw std::runtime_error(flag + " needs a value");
    const char* value = argv[i + 1];
    if (flag == "--space") {
      o.space = value;
    } else if (flag == "--seeds") {
      const std::string text = value;
      const auto colon = text.find(':');
      o.first = static_cast<long>(number(flag, text.substr(0, colon).c_str()));
      o.end = colon == std::string::npos ? o.first + 1
                                         : static_cast<long>(number(flag, text.substr(colon + 1).c_str()));
      if (o.first < 0 || o.end <= o.first)
        throw std::runtime_error("--seeds needs FIRST:END with 0 <= FIRST < END, got " + text);
    } else if (flag == "--time") {
      o.time = number(flag, value);
    } else if (flag == "--radius") {
      o.radius = number(flag, value);
    } else if (flag == "--tolerance") {
      o.tolerance = number(flag, value);
    } else if (flag == "--check-tolerance") {
      o.check_tolerance = number(flag, value);
    } else if (flag == "--resolution") {
      o.resolution = number(flag, value);
    } else {
      throw std::runtime_error("unknown option " + flag + "; see the usage at the top of sphere_demo.cpp");
    }
  }
  if (o.time <= 0 || o.radius <= 0 || o.radius > 2 || o.tolerance <= 0 || o.resolution <= 0 || o.check_tolerance < 0)
    throw std::runtime_error("--time, --tolerance and --resolution must be positive, --radius in (0, 2], "
                             "--check-tolerance >= 0");
  return o;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const Options o = parse(argc, argv);
    for (long seed = o.first; seed < o.end; ++seed) run(o, seed);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "sphere_demo: %s\n", e.what());
    return 1;
  }
}
