// The planning problem the Python side exports (see manifoldgen/ompl_native.py): our constraint
// (equalities, and inequalities for the validity test) and our validity checker, built with pinocchio and coal from the same model,
// collision model, collision pairs and obstacles as manifoldgen's ConstrainedSpace.
//
// This header shows only Eigen and the standard library: problem.cpp is compiled against the
// pin wheel's Boost (1.90), main.cpp against Debian's (1.74, which libompl was built with).
#pragma once

#include <Eigen/Core>

#include <memory>
#include <string>
#include <vector>

namespace mgnative {

// Operations since construction, counted where they happen.
struct Counts {
  long fk = 0;                // configurations whose constraint kinematics was computed (residual or Jacobian)
  long jacobians = 0;         // of those, with the Jacobian
  long collision_checks = 0;  // configurations checked by coal (with sphere models: those the spheres flagged)
  long sphere_checks = 0;     // configurations whose sphere models were tested first (0 without sphere models)
  long inequalities = 0;      // configurations whose inequalities (CoM margin, hemisphere) were evaluated
};

struct Settings {
  std::string space;       // projected, atlas or tangent
  double delta = 0.05;     // OMPL's manifold step (rad)
  double lambda = 2.0;     // OMPL's limit on manifold-walk length / chord length
  double range = 0.6;      // RRTConnect's range (rad); 0: OMPL's default
  double tolerance = 0.95; // OMPL's tolerance on || F_i / tol_i ||_2
  int max_iterations = 50; // Newton iterations per projection
  double time_limit = 1.0; // seconds, for the whole query
  unsigned long seed = 0;
  int shortcut = 0;        // OMPL PathSimplifier::shortcutPath attempts on an accepted path (0: none)
  // the atlas's own knobs (atlas and tangent spaces; OMPL's defaults): a chart's validity region (epsilon: distance
  // to the manifold, alpha: angle to it, rho: radius, 0: OMPL's 5 delta), the share of samples on the frontier
  // (exploration) and whether charts are separated by their neighbours' half-spaces
  double epsilon = 0.05, rho = 0.0, alpha = 0.39269908169872414, exploration = 0.75;
  bool separated = true;
};

class Problem {
 public:
  explicit Problem(const std::string& json_path);  // throws std::runtime_error with a one-line message
  ~Problem();

  int n() const;  // active coordinates
  int m() const;  // residual components
  int g() const;  // inequality rows (0: none)
  const Settings& settings() const;
  const Eigen::VectorXd& lower() const;
  const Eigen::VectorXd& upper() const;
  const Eigen::VectorXd& start() const;
  const Eigen::VectorXd& goal() const;
  const Eigen::VectorXd& tolerance() const;  // (m,) our per-component tolerances

  // F(q, y) (m,), unscaled (metres, radians), and dF/dq (m, n).
  void residual(const Eigen::Ref<const Eigen::VectorXd>& q, Eigen::Ref<Eigen::VectorXd> out);
  void jacobian(const Eigen::Ref<const Eigen::VectorXd>& q, Eigen::Ref<Eigen::MatrixXd> out);
  bool within_limits(const Eigen::Ref<const Eigen::VectorXd>& q) const;
  bool collision_free(const Eigen::Ref<const Eigen::VectorXd>& q);
  // every inequality G_i(q) <= 0 (the CoM over the support polygon with its margin, a hemisphere)
  bool inequalities_hold(const Eigen::Ref<const Eigen::VectorXd>& q);

  Counts counts;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace mgnative
