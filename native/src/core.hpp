// manifoldgen's compiled planning core: the constrained space (constraint residuals and Jacobians,
// projection, the validity rule, motion and path checks) and RRT-Connect, with pinocchio and coal.
//
// Arrays of configurations are row-major (rows = configurations), as numpy's. The rules and
// algorithms are those of the Python reference (manifoldgen/space.py, constraints/projection.py,
// planning/local.py, base.py, rrt_connect.py); tests/test_native.py compares the two.
#pragma once

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace mgcore {

using Vec = Eigen::VectorXd;
using RowMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// The validity tests, in the order they run (manifoldgen.space.REASONS, 1-based; 0: valid).
enum Reason { VALID = 0, LIMITS = 1, CONSTRAINT = 2, INEQUALITY = 3, COLLISION = 4 };

// Operations since construction, counted where they happen (the Python space's counters).
struct Counters {
  long evaluations = 0;       // configurations whose residual alone was evaluated
  long jacobians = 0;         // configurations whose residual and Jacobian were evaluated
  long projection_steps = 0;  // projection iterations, summed over rows
  long collision_checks = 0;  // configurations checked with coal (exact meshes)
  long sphere_checks = 0;     // configurations checked with the sphere models first (coal only where they touch)
  long sweep_checks = 0;      // certified sweep tests of spans of dense path states (validate_path, spheres set)
  long hull_tests = 0;        // pair tests on convex outer shapes (the mid phase, per state and per sweep)
  long mesh_tests = 0;        // pair tests with coal's exact test of the geometries (after the mid phase)
  std::array<long, 5> stopped{};  // motion checks that stopped short, by reason
  long callback_calls = 0;  // calls into Python constraint callbacks (residuals, Jacobians, inequalities)
  long callback_rows = 0;   // configurations those calls evaluated
};

// Constraint terms evaluated in Python (a user's constraint; see Space::add_callback): one call
// evaluates B configurations q (B, n). Residuals fill F (B, rows) and, when J is not null,
// J (B, rows, n) row-major; inequalities fill G (B, p). They may throw (the exception ends the call).
using Residuals = std::function<void(const double* q, long B, double* F, double* J)>;
using Inequalities = std::function<void(const double* q, long B, double* G)>;

// ---------------------------------------------------------------- Compiled expressions (expression.cpp)
// A user's residual (or inequality) traced once in Python (manifoldgen/constraints/trace.py) into straight-line
// code on scalar registers: register i holds instruction i's value and, when derivatives are asked for, its
// gradient over the n active coordinates (forward mode). Python reads these codes from the binding
// (manifoldgen_core.Op); the operands a, b are as noted.
enum class Op : int {
  // leaves
  Q,      // q[a]
  CONST,  // constants[a]
  POS,    // frame slot a's world position [b]
  ROT,    // frame slot a's world rotation (b / 3, b % 3)
  COM,    // the centre of mass [b]
  // unary: f(register a)
  NEG,
  SQRT,
  SIN,
  COS,
  TAN,
  ASIN,
  ACOS,
  ATAN,
  EXP,
  LOG,
  ABS,  // derivative sign(a), 0 at 0
  TANH,
  // binary: f(register a, register b)
  ADD,
  SUB,
  MUL,
  DIV,
  POW,
  ATAN2,  // atan2(a, b)
  MAX,    // NaN if either is (numpy's maximum); derivative of a where a >= b, else of b
  MIN,    // NaN if either is (numpy's minimum); derivative of a where a <= b, else of b
};

struct Instruction {
  Op op;
  int a = 0, b = 0;
};

// What an expression reads at one configuration, filled by the space from pinocchio: q (n,); per frame slot its
// world position and rotation and, for derivatives, its Jacobian (6, n) over the active coordinates (rows: the
// origin's linear velocity, then the angular velocity, world axes); the centre of mass and its Jacobian (3, n).
struct Leaves {
  const double* q = nullptr;
  std::vector<Eigen::Vector3d> position;
  std::vector<Eigen::Matrix3d> rotation;
  std::vector<RowMat> jacobian;
  Eigen::Vector3d com = Eigen::Vector3d::Zero();
  RowMat com_jacobian;
};

class Expression {
 public:
  // code: register i is instruction i's result; constants; frames: pinocchio frame ids by slot; outputs: the
  // registers of the result rows; n: active coordinates. Throws std::invalid_argument for an operand that is not
  // an earlier register, a constant, a frame slot, an axis or a coordinate.
  Expression(std::vector<Instruction> code, std::vector<double> constants, std::vector<int> frames,
             std::vector<int> outputs, int n);
  int rows() const { return static_cast<int>(outputs_.size()); }
  const std::vector<int>& frames() const { return frames_; }
  bool uses_com() const { return uses_com_; }
  // Leaves sized for this expression (q unset).
  Leaves leaves() const;
  // F (rows,) at leaves; with J (rows, n) row-major when J is not null (the leaves' Jacobians are read then).
  void evaluate(const Leaves& leaves, double* F, double* J = nullptr);

 private:
  std::vector<Instruction> code_;
  std::vector<double> constants_;
  std::vector<int> frames_, outputs_;
  int n_;
  bool uses_com_ = false;
  std::vector<char> varies_;             // per register: its gradient can be non-zero
  std::vector<double> value_, gradient_;  // per register: value; gradient (n each)
};

struct Projection {
  bool converged;
  int iterations;
  double residual;  // final max |F_i|
};

struct PathCheck {
  bool valid;
  double worst;        // max |F_i| / tol_i over the checked states
  long first_invalid;  // index of the first invalid dense state (-1: none)
  int reason;          // its Reason
  int segment;         // the path segment it lies on (-1: none)
  long states;         // dense states in the path
};

// An active joint: where it sits in pinocchio's q and v (nq = 2: a continuous joint, cos/sin). nq = 7:
// pinocchio's free flyer, first in the list, six coordinates (x, y, z, yaw, pitch, roll) as manifoldgen.robot
// has them (ZYX Euler: R = Rz(yaw) Ry(pitch) Rx(roll)); every other entry is one coordinate.
struct Active {
  int idx_q, idx_v, nq;
};
constexpr int FREE_FLYER = 7;

// A built-in constraint term's fields, read by name (a Python dict in the binding, a JSON object in the C++ OMPL
// baseline); each accessor throws std::invalid_argument naming a field that is missing.
struct TermFields {
  virtual ~TermFields() = default;
  virtual int integer(const char* name) const = 0;
  virtual double number(const char* name) const = 0;
  virtual std::vector<int> ints(const char* name) const = 0;
  virtual Vec vector(const char* name) const = 0;
  virtual RowMat rows(const char* name) const = 0;  // a list of equal-length rows
};

class Space {
 public:
  // model_file / geometry_file: pinocchio binary serializations of the robot model and of the
  // collision model (geometries, obstacles, the exact collision pairs); reference (model.nq): the
  // locked joints; lower/upper (n): joint limits; margin: intermediate motion states keep within
  // (1 - margin) x tolerance; resolution: spacing of the dense path check. Throws std::runtime_error.
  Space(const std::string& model_file, const std::string& geometry_file, const Vec& reference,
        const std::vector<Active>& active, const Vec& lower, const Vec& upper, double margin, double resolution);
  ~Space();

  // Constraint terms, stacked in the order added (the condition y is baked in).
  // A built-in term by its type name (builtin_terms.cpp: pose, chain, sphere, orientation, linear; the inequalities
  // com_polygon, hemisphere) with its fields; throws std::invalid_argument naming an unknown type or a bad field.
  void add_term(const std::string& kind, const TermFields& fields);
  static std::vector<std::string> built_in_terms();  // the type names add_term knows
  // expression: F = a compiled user residual's outputs (Expression above); its frame ids are checked here
  void add_expression(Expression expression);
  // Inequalities G(q) <= 0, stacked in the order added (checked after the equalities, before collision).
  // expression: G = a compiled user inequality's outputs
  void add_expression_inequality(Expression expression);
  int g() const;                                    // built-in and compiled inequality rows
  void inequality(const double* q, double* G);      // (g,)
  bool inequalities_hold(const double* q);          // every G_i <= 0 (true when there is none)
  // callback: `rows` residual components from Python, stacked in order like the built-in terms.
  void add_callback(int rows, Residuals residuals);
  // G(q) <= 0 from Python, p components (at most one; replaces the previous one).
  void set_inequalities(int p, Inequalities inequalities);
  void set_tolerance(const Vec& tolerance);  // (m,) after the terms
  // Conservative sphere models (see set_spheres in module.cpp): joint (S,), center (S, 3) in the
  // joint frame, radius (S,), geometry (S,) the robot geometry each covers.
  // exact: geometry pairs left to coal all the same (spheres that touch while the meshes are apart).
  void set_spheres(const std::vector<int>& joint, const RowMat& center, const Vec& radius,
                   const std::vector<int>& geometry, const std::vector<std::pair<int, int>>& exact = {});
  void clear_spheres();
  bool has_spheres() const;
  // Certified sweeps (sweeps.cpp, "Certified sweeps"): with sphere models set, validate_path tests whole spans of
  // consecutive dense states at once and checks single states only where a span cannot be certified; the same
  // PathCheck as state by state. On by default; off: state by state. sweeps() says whether they are used.
  void set_sweeps(bool on);
  bool sweeps() const;
  // What the first certified path check would otherwise build (each constraint row's rate bounds over the
  // coordinates: certified constraint checks and sweeps), built now, once the terms are added: when the space
  // is made, not in the first query's time. Again only after terms or spheres change.
  void prepare();
  std::string sweep_report() const;  // why sweeps are unavailable ("" when they are)
  // The states (k, n) taken as consecutive dense states of a path: true when every state of the polyline through
  // them is certified collision-free (one sweep test; counted). Needs sweeps().
  bool sweep_free(const double* states, int k);
  // (S,) bounds on how far each sphere centre moves from the middle state (k / 2) along the polyline through
  // states (k, n) (what sweep_free inflates the spheres by, before relative motion is taken out).
  // common >= 0: in the frame of the sphere's joint's support at that depth, moved by the deeper joints only (a
  // pair's relative motion; NaN where the chain is not that deep). rates: the rate bound over every coordinate
  // that the sphere and primitive tests try first instead (common ignored).
  std::vector<double> sweep_bounds(const double* states, int k, int common = -1, bool rates = false);
  // (S, 3) world centres of the spheres at q (n,).
  RowMat sphere_centers(const double* q);
  std::string sphere_report() const;  // what the sphere check covers, for people

  int n() const;
  int m() const;
  int p() const;         // inequality components from Python (0: none)
  bool batched() const;  // Python callbacks take part: configurations are evaluated in batches
  double margin() const;
  double resolution() const;
  const Vec& tolerance() const;

  // One configuration q (n,) at a time.
  void residual(const double* q, double* F);               // counted as an evaluation
  void jacobian(const double* q, double* F, double* J);    // J (m, n) row-major; counted as a Jacobian
  double violation(const double* q);                       // max |F_i| / tol_i
  bool within_limits(const double* q) const;
  // Exact verdict (coal); with sphere models set, a state whose spheres touch nothing is free without coal.
  bool collision_free(const double* q);
  bool spheres_free(const double* q);  // the sphere models' verdict alone (conservative), else exact
  // first failed test (limits, equality within limit x tolerance, inequalities, collision), lazily;
  // exact = false: the sphere models' verdict alone
  int code(const double* q, double limit, bool collision, bool exact);

  // A motion's states (k, n) in order: how many leading ones are valid (intermediate states within the
  // margin, the last one, when it is a node, the plain tolerance); sets stop and counts stopped.
  // collision = false: the collision test is left out (a lazy search checks collisions later).
  int valid_prefix(const double* states, int k, bool last_is_node, bool collision = true);
  Projection project(double* q, double tol, int max_iters, double damping, double max_step);
  // Every state every resolution along path (K, n), exact collision checks (with sphere models and sweeps():
  // spans of states certified at once, the same report). certify (built-in terms other than closed chains): a state
  // the constraint's rates certify from the latest evaluated one passes without being evaluated (sweeps.cpp,
  // "Certified constraints"): the same verdict, first invalid state, reason, segment and state count; worst: over
  // the states evaluated.
  PathCheck validate_path(const double* path, int K, bool certify = false);

  // Batches of B configurations q (B, n) row-major: one Python call per callback term serves them all.
  void residuals(const double* q, long B, double* F);            // F (B, m); B evaluations
  void jacobians(const double* q, long B, double* F, double* J);  // F (B, m), J (B, m, n); B Jacobians
  void violations(const double* q, long B, double* v);            // (B,) max |F_i| / tol_i
  void inequalities(const double* q, long B, double* G);          // G (B, p)
  // (B,) first failed test of each row (limit (B,)); batched(): limits, equalities and inequalities of
  // every row at once (as the Python space does), collisions then row by row; else lazily per row.
  void codes(const double* q, long B, const double* limit, bool collision, bool exact, int* out);
  // project() of every row in place, the rows still iterating evaluated together at each iteration.
  void project_many(double* q, long B, double tol, int max_iters, double damping, double max_step, Projection* out);

  Counters counts;
  int stop = VALID;  // reason of the latest motion check's stop (VALID: it passed)

  struct Impl;  // its private parts (space_impl.hpp), named by the terms that read them

 private:
  std::unique_ptr<Impl> impl_;
  // validate_path's dense states (M, n) and their segments, checked with certified sweeps
  PathCheck sweep_path(const std::vector<double>& states, const std::vector<int>& segment, bool certify);
};

// RRT-Connect settings, filled whole from Python (manifoldgen.planning.rrt_connect.core_settings: the planner's
// settings dataclass is their one source; the binding's constructor takes every field, and there are no defaults here).
struct PlannerSettings {
  double range, resolution, step;
  bool partial;
  int pool, pool_batch, candidates, target_batch;
  std::string local;  // the local planner: auto, interpolate, project or direct
  // edge_stride: coarse-first edge checks: a motion's planning-resolution states are checked for collision every
  // edge_stride-th and at nodes while searching, the rest when the edge lies on a candidate path (1: every state
  // at once); with dense_edges, each motion passes the path check (Space::validate_path) when it is made, after a
  // pre-check of its every edge_stride-th planning-resolution state (all tests, bisection order), so a candidate
  // path is made of checked edges and is never rejected (planner.cpp, Local::dense)
  int edge_stride;
  bool dense_edges;
  // draw returns raw candidates; a candidate becomes a sample (refine >= 0 projection iterations, then limits
  // and constraint) only when the search first uses it (see planner.cpp)
  int refine;
  // reach > 0: a pooled sample is a stepping stone of a tree within min(reach, range) of one of its nodes
  // (else range)
  double reach;
  // shortcut > 0: a found path is shortened by that many shortcut attempts (planner.cpp Search::shorten; the
  // Python planners' planning/smoothing.py draws the same points), each kept only when its stretch passes the path
  // check, then relaxed (Search::relax)
  int shortcut;
  // projections: a projected walk's steps go to precision x the smallest tolerance in at most max_iters iterations
  // (planning/local.py's), a raw row's refinement to tol; both with damping and max_step (constraints/projection.py)
  double precision;
  int max_iters;
  double tol, damping, max_step;
};

struct PlanOutput {
  RowMat path;  // (K, n); 0 rows: unsolved
  long iterations = 0, samples = 0, rejected = 0, out_of_reach = 0, projections = 0, cut_edges = 0;
  long verified_states = 0;  // states of coarse edges checked for collision on candidate paths (Search::verify)
  long reattached = 0;  // cut edges whose node found another parent (the rest left the search with their subtrees)
  long refined = 0, accepted = 0;  // raw candidates made samples when first used, and of those valid
  long shortcuts = 0;  // shortcuts kept (settings.shortcut)
  long relaxed = 0;  // waypoint moves kept by the relaxation after them
  double found_length = 0;  // the path's length before its shortcuts
  std::vector<long> nodes;
};

// draw(count) -> (count, n) valid configurations from the sampler (may throw: the exception ends the query).
using Draw = std::function<RowMat(int)>;

PlanOutput rrt_connect(Space& space, const Vec& start, const Vec& goal, const Draw& draw,
                       const PlannerSettings& settings, double time_limit);

// The search's nearest-neighbour index (a k-d tree, planner.cpp) over points (N, n), rows inserted in order,
// asked for each query row (Q, n): the nearest row with alive[i] (ties: the lowest index; -1: none alive) and
// whether an alive row lies within radius. For tests against brute force.
struct NearestAnswers {
  std::vector<int> nearest;
  std::vector<char> within;
};
NearestAnswers nearest_queries(const RowMat& points, const std::vector<char>& alive, const RowMat& queries,
                               double radius);

// A generative model's sampling network (models/base.py: the CVAE's decoder, a GAN's generator), run in the core:
// latent rows z (B, latent), N(0, I) or U(-1, 1), then Linear layers with SiLU between them on [z, normalised y];
// the output is de-normalised (q_mean + out * q_std) and clipped to the joint limits. float32, as torch runs it.
// With steps > 0 the network is a velocity field v([x, normalised y, t]) (models/cfm.py; latent = d) and a decode
// integrates dx/dt = v from x = z at t = 0 to t = 1 in that many steps (steps - 1 Heun steps, then one Euler
// step) before de-normalising.
class Decoder {
 public:
  using MatF = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  using VecF = Eigen::VectorXf;
  // Linear layers with SiLU between them: weights[i] (out_i, in_i) and biases[i] (out_i,) in torch's layout.
  struct Net {
    std::vector<MatF> weights;
    std::vector<VecF> biases;
    MatF forward(const MatF& x) const;  // the network on x (B, in_0): (B, out_last)
  };
  // in_0 = latent + y_mean.size(), out_last = q_mean.size(); q_std, lower, upper as q_mean, y_std as y_mean
  // (invalid_argument otherwise); steps > 0: in_0 = latent + y_mean.size() + 1 and latent = q_mean.size().
  // prior_steps > 0: the latent rows are first carried by the velocity field prior([z, y, t]) (in_0 = latent +
  // y_mean.size() + 1, out_last = latent), integrated as the network is when steps > 0.
  Decoder(std::vector<MatF> weights, std::vector<VecF> biases, int latent, bool uniform, const Vec& q_mean,
          const Vec& q_std, const Vec& y_mean, const Vec& y_std, const Vec& lower, const Vec& upper, int steps = 0,
          std::vector<MatF> prior_weights = {}, std::vector<VecF> prior_biases = {}, int prior_steps = 0);
  // (count, latent) latent rows from seed (xoshiro256** seeded by splitmix64; Box-Muller for N(0, I)).
  MatF latent_rows(long count, std::uint64_t seed) const;
  // (B, d) configurations decoded from z (B, latent) at condition y (k,).
  RowMat decode(const MatF& z, const Vec& y) const;
  RowMat sample(const Vec& y, long count, std::uint64_t seed) const { return decode(latent_rows(count, seed), y); }

 private:
  Net net_, prior_;
  int latent_;
  bool uniform_;
  int steps_, prior_steps_;
  VecF q_mean_, q_std_, y_mean_, y_std_;
  Vec lower_, upper_;
};

}  // namespace mgcore
