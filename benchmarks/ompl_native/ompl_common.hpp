// What the two OMPL programs (ompl_native, sphere_demo) share: process CPU and wall clocks, and the
// constrained state space named projected, atlas or tangent with its space information.
#pragma once

#include <ompl/base/ConstrainedSpaceInformation.h>
#include <ompl/base/spaces/constraint/AtlasStateSpace.h>
#include <ompl/base/spaces/constraint/ProjectedStateSpace.h>
#include <ompl/base/spaces/constraint/TangentBundleStateSpace.h>

#include <chrono>
#include <ctime>
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

}  // namespace ompl_common
