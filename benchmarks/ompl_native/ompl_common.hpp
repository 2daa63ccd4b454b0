// What the two OMPL programs (ompl_native, sphere_demo) share: process CPU and wall clocks, and the
// constrained state space named projected, atlas or tangent with its space information.
#pragma once

#include <ompl/base/ConstrainedSpaceInformation.h>
#include <ompl/base/spaces/constraint/AtlasStateSpace.h>
#include <ompl/base/spaces/constraint/ProjectedStateSpace.h>
#include <ompl/base/spaces/constraint/TangentBundleStateSpace.h>

#include <ompl/base/PlannerData.h>
#include <ompl/geometric/SimpleSetup.h>

#include <chrono>
#include <ctime>
#include <functional>
#include <stdexcept>
#include <string>
#include <utility>

namespace ompl_common {

inline double cpu_seconds() {
  timespec t;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}

inline double wall_seconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// The constrained space `name` (projected, atlas, tangent) over `ambient`, and its space information.
inline std::pair<ompl::base::ConstrainedStateSpacePtr, ompl::base::SpaceInformationPtr> constrained_space(
    const std::string& name, const ompl::base::StateSpacePtr& ambient, const ompl::base::ConstraintPtr& constraint) {
  namespace ob = ompl::base;
  if (name == "projected") {
    auto space = std::make_shared<ob::ProjectedStateSpace>(ambient, constraint);
    return {space, std::make_shared<ob::ConstrainedSpaceInformation>(space)};
  }
  if (name == "atlas") {
    auto space = std::make_shared<ob::AtlasStateSpace>(ambient, constraint);
    return {space, std::make_shared<ob::ConstrainedSpaceInformation>(space)};
  }
  if (name == "tangent") {
    auto space = std::make_shared<ob::TangentBundleStateSpace>(ambient, constraint);
    return {space, std::make_shared<ob::TangentBundleSpaceInformation>(space)};
  }
  throw std::runtime_error("unknown OMPL space '" + name + "'; known: projected, atlas, tangent");
}

// What solve_with_retries did: accepted a path, OMPL's last status, solve calls, refused paths, tree vertices
// summed over the calls.
struct Outcome {
  bool solved = false;
  std::string status = "not run";
  int attempts = 0, rejected = 0;
  long vertices = 0;
};

// Solve until `accept` takes an interpolated path or the time left (`time_limit` s after wall-clock `wall0`)
// runs out: a refused path does not end the query, the planner starts over (the retry policy every method
// of the benchmarks shares).
inline Outcome solve_with_retries(ompl::geometric::SimpleSetup& setup, const ompl::base::SpaceInformationPtr& si,
                                  double time_limit, double wall0,
                                  const std::function<bool(ompl::geometric::PathGeometric&)>& accept) {
  Outcome out;
  while (!out.solved) {
    const double remaining = time_limit - (wall_seconds() - wall0);
    if (remaining <= 0) break;
    if (out.attempts++) setup.clear();
    out.status = setup.solve(remaining).asString();
    ompl::base::PlannerData data(si);
    setup.getPlannerData(data);
    out.vertices += data.numVertices();
    if (!setup.haveExactSolutionPath()) break;  // out of time (RRTConnect stops only then)
    ompl::geometric::PathGeometric path = setup.getSolutionPath();
    path.interpolate();
    out.solved = accept(path);
    out.rejected += !out.solved;
  }
  return out;
}

}  // namespace ompl_common
