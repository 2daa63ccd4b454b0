// OMPL's constrained planning (Projected / Atlas / TangentBundle + RRTConnect) with our constraint
// (the compiled core's terms) and validity checker compiled (problem.hpp), driven by manifoldgen over a pipe.
//
//   ompl_native PROBLEM.json            plan (protocol below)
//   ompl_native --evaluate PROBLEM.json  read configurations (n numbers a line) on stdin; print for
//                                        each: F (m), dF/dq (m x n, row-major), collision-free (0/1)
//
// Protocol (one line each, stdout answers, stdin asks): "ready LOAD_S" -> "go TIME_LIMIT";
// then for every exact OMPL solution "path K" and K lines of n numbers -> "valid" or "invalid"
// (manifoldgen's dense check decides; on "invalid" the search restarts within the remaining time,
// the atlas keeps its charts); with settings.shortcut > 0, an accepted path is shortened by OMPL's
// PathSimplifier::shortcutPath (that many attempts, interpolated on the manifold) and sent again the same
// way: "valid" makes it the answer, "invalid" keeps the accepted one; finally "done {JSON}" with the outcome,
// the accepted path's length before shortening (found_length) and the operation counts
// (constraint FK evaluations, Jacobians, inequality evaluations (each with its own FK), collision checks,
// samples OMPL's sampler drew).
//
// Inequalities (the CoM margin of balance, orientation's hemisphere) are not OMPL constraints: the state
// validity checker tests them after the joint limits, before collision, as manifoldgen's rule orders them.
// A floating base's six coordinates are plain real coordinates with the task's base_bounds, as manifoldgen's.
//
// Tolerance: OMPL tests || F_i / tol_i ||_2 <= t with t = settings.tolerance (1 - margin): our
// residual scaled component-wise by our tolerances, as manifoldgen's Python OMPL bridge does.
#include "problem.hpp"
#include "ompl_common.hpp"

#include <ompl/base/Constraint.h>
#include <ompl/base/PlannerData.h>
#include <ompl/base/spaces/RealVectorStateSpace.h>
#include <ompl/base/spaces/constraint/AtlasStateSpace.h>
#include <ompl/geometric/PathSimplifier.h>
#include <ompl/geometric/SimpleSetup.h>
#include <ompl/geometric/planners/rrt/RRTConnect.h>
#include <ompl/util/Console.h>
#include <ompl/util/RandomNumbers.h>

#include <cstdio>
#include <iostream>
#include <sstream>
#include <string>

namespace ob = ompl::base;
namespace og = ompl::geometric;

namespace {

using ompl_common::cpu_seconds;
using ompl_common::wall_seconds;

// Our constraint at a fixed y, residual and Jacobian rows divided by our per-component tolerances.
class ScaledConstraint : public ob::Constraint {
 public:
  ScaledConstraint(mgnative::Problem& problem)
      : ob::Constraint(problem.n(), problem.m(), problem.settings().tolerance),
        problem_(problem),
        scale_(problem.tolerance().cwiseInverse()) {
    setMaxIterations(problem.settings().max_iterations);
  }

  void function(const Eigen::Ref<const Eigen::VectorXd>& x, Eigen::Ref<Eigen::VectorXd> out) const override {
    problem_.residual(x, out);
    out.array() *= scale_.array();
  }

  void jacobian(const Eigen::Ref<const Eigen::VectorXd>& x, Eigen::Ref<Eigen::MatrixXd> out) const override {
    problem_.jacobian(x, out);
    out.array().colwise() *= scale_.array();
  }

  bool project(Eigen::Ref<Eigen::VectorXd> x) const override {
    ++projections;
    return ob::Constraint::project(x);
  }

  mutable long projections = 0;

 private:
  mgnative::Problem& problem_;
  Eigen::VectorXd scale_;
};

// OMPL's own state sampler, counting the samples it draws.
class CountingSampler : public ob::StateSampler {
 public:
  CountingSampler(const ob::StateSpace* space, ob::StateSamplerPtr inner, long& count)
      : ob::StateSampler(space), inner_(std::move(inner)), count_(count) {}
  void sampleUniform(ob::State* state) override {
    ++count_;
    inner_->sampleUniform(state);
  }
  void sampleUniformNear(ob::State* state, const ob::State* near, double distance) override {
    ++count_;
    inner_->sampleUniformNear(state, near, distance);
  }
  void sampleGaussian(ob::State* state, const ob::State* mean, double std_dev) override {
    ++count_;
    inner_->sampleGaussian(state, mean, std_dev);
  }

 private:
  ob::StateSamplerPtr inner_;
  long& count_;
};

// RRTConnect drawing from a CountingSampler around the space's own sampler (the atlas ignores a
// sampler allocator, so the planner's sampler is wrapped instead).
class CountingRRTConnect : public og::RRTConnect {
 public:
  explicit CountingRRTConnect(const ob::SpaceInformationPtr& si) : og::RRTConnect(si) {}
  ob::PlannerStatus solve(const ob::PlannerTerminationCondition& ptc) override {
    if (!sampler_) sampler_ = std::make_shared<CountingSampler>(si_->getStateSpace().get(), si_->allocStateSampler(), samples);
    return og::RRTConnect::solve(ptc);
  }
  long samples = 0;
};

std::string expect(const std::string& word) {
  std::string line;
  if (!std::getline(std::cin, line) || line.compare(0, word.size(), word) != 0)
    throw std::runtime_error("expected '" + word + "' from manifoldgen, got '" + line + "'");
  return line.substr(word.size());
}

void write_path(const og::PathGeometric& path, int n) {
  std::printf("path %zu\n", path.getStateCount());
  for (std::size_t k = 0; k < path.getStateCount(); ++k) {
    const Eigen::Map<Eigen::VectorXd>& x = *path.getState(k)->as<ob::ConstrainedStateSpace::StateType>();
    for (int i = 0; i < n; ++i) std::printf(i ? " %.17g" : "%.17g", x[i]);
    std::printf("\n");
  }
  std::fflush(stdout);
}

int plan(mgnative::Problem& problem, double load_s) {
  const mgnative::Settings& settings = problem.settings();
  const int n = problem.n();
  ompl::msg::setLogLevel(ompl::msg::LOG_NONE);  // OMPL complains when seeded after its first numbers
  ompl::RNG::setSeed(static_cast<std::uint_fast32_t>(settings.seed % 2147483647UL + 1));
  ompl::msg::setLogLevel(ompl::msg::LOG_WARN);  // warnings and errors go to stderr, never stdout
  std::printf("ready %.6f\n", load_s);
  std::fflush(stdout);
  const double time_limit = std::stod(expect("go "));
  const double cpu0 = cpu_seconds(), wall0 = wall_seconds();

  auto ambient = std::make_shared<ob::RealVectorStateSpace>(n);
  ob::RealVectorBounds bounds(n);
  for (int i = 0; i < n; ++i) {
    bounds.setLow(i, problem.lower()[i]);
    bounds.setHigh(i, problem.upper()[i]);
  }
  ambient->setBounds(bounds);
  auto constraint = std::make_shared<ScaledConstraint>(problem);
  const auto [space, si] = ompl_common::constrained_space(settings.space, ambient, constraint);
  space->setDelta(settings.delta);
  space->setLambda(settings.lambda);
  // the inequalities (CoM margin, hemisphere) through state validity, as the Python-callback OMPL bridge takes them
  si->setStateValidityChecker([&problem](const ob::State* state) {
    const Eigen::Map<Eigen::VectorXd>& x = *state->as<ob::ConstrainedStateSpace::StateType>();
    return problem.within_limits(x) && problem.inequalities_hold(x) && problem.collision_free(x);
  });

  og::SimpleSetup setup(si);
  ob::ScopedState<> start(space), goal(space);
  start->as<ob::ConstrainedStateSpace::StateType>()->copy(problem.start());
  goal->as<ob::ConstrainedStateSpace::StateType>()->copy(problem.goal());
  for (auto* end : {&start, &goal})
    if (!constraint->isSatisfied(end->get()))
      throw std::runtime_error("start or goal is within our tolerance but not within OMPL's stricter one");
  if (settings.space != "projected") {
    auto atlas = std::static_pointer_cast<ob::AtlasStateSpace>(space);
    atlas->setEpsilon(settings.epsilon);
    atlas->setAlpha(settings.alpha);
    atlas->setExploration(settings.exploration);  // before rho: it resets the sampling radius from rho
    atlas->setRho(settings.rho > 0 ? settings.rho : 5 * settings.delta);
    atlas->setSeparated(settings.separated);
    atlas->anchorChart(start.get());
    atlas->anchorChart(goal.get());
  }
  setup.setStartAndGoalStates(start, goal);
  auto planner = std::make_shared<CountingRRTConnect>(si);
  if (settings.range > 0) planner->setRange(settings.range);
  setup.setPlanner(planner);
  setup.setup();

  auto answer = [&](og::PathGeometric& path) {
    write_path(path, n);  // the caller's dense check answers
    std::string verdict;
    std::getline(std::cin, verdict);
    return verdict == "valid";
  };
  double found_length = 0.0;
  const ompl_common::Outcome run =
      ompl_common::solve_with_retries(setup, si, time_limit, wall0, [&](og::PathGeometric& path) {
        found_length = path.length();
        return answer(path);
      });
  bool shortened = false;
  if (run.solved && settings.shortcut > 0) {  // OMPL's shortcuts on the accepted path, checked by the caller again
    og::PathGeometric path = setup.getSolutionPath();
    og::PathSimplifier(si).shortcutPath(path, settings.shortcut, settings.shortcut);
    path.interpolate();
    shortened = answer(path);
  }
  const double wall = wall_seconds() - wall0, cpu = cpu_seconds() - cpu0;
  long charts = settings.space == "projected" ? 0 : std::static_pointer_cast<ob::AtlasStateSpace>(space)->getChartCount();
  std::printf(
      "done {\"solved\": %s, \"status\": \"%s\", \"attempts\": %d, \"rejected_paths\": %d, \"vertices\": %ld, "
      "\"charts\": %ld, \"projections\": %ld, \"samples\": %ld, \"fk\": %ld, \"jacobians\": %ld, \"inequalities\": %ld, \"collision_checks\": %ld, "
      "\"found_length\": %.6f, \"shortened\": %s, "
      "\"sphere_checks\": %ld, "
      "\"wall_s\": %.6f, \"cpu_s\": %.6f, \"load_s\": %.6f}\n",
      run.solved ? "true" : "false", run.status.c_str(), run.attempts, run.rejected, run.vertices, charts,
      constraint->projections,
      planner->samples,
      problem.counts.fk, problem.counts.jacobians, problem.counts.inequalities, problem.counts.collision_checks,
      found_length, shortened ? "true" : "false",
      problem.counts.sphere_checks, wall, cpu, load_s);
  std::fflush(stdout);
  return 0;
}

int evaluate(mgnative::Problem& problem) {
  const int n = problem.n(), m = problem.m();
  Eigen::VectorXd q(n), F(m);
  Eigen::MatrixXd J(m, n);
  std::string line;
  while (std::getline(std::cin, line)) {
    std::istringstream in(line);
    for (int i = 0; i < n; ++i) in >> q[i];
    if (!in) throw std::runtime_error("each configuration line needs " + std::to_string(n) + " numbers");
    problem.residual(q, F);
    problem.jacobian(q, J);
    for (int i = 0; i < m; ++i) std::printf("%.17g ", F[i]);
    for (int i = 0; i < m; ++i)
      for (int j = 0; j < n; ++j) std::printf("%.17g ", J(i, j));
    std::printf("%d\n", problem.collision_free(q) ? 1 : 0);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  const bool eval = argc == 3 && std::string(argv[1]) == "--evaluate";
  if (argc != 2 && !eval) {
    std::fprintf(stderr, "usage: ompl_native PROBLEM.json | ompl_native --evaluate PROBLEM.json\n");
    return 2;
  }
  try {
    const double wall0 = wall_seconds();
    mgnative::Problem problem(argv[eval ? 2 : 1]);
    return eval ? evaluate(problem) : plan(problem, wall_seconds() - wall0);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "ompl_native: %s\n", e.what());
    return 1;
  }
}
