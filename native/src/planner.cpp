// RRT-Connect in C++ (see core.hpp): manifoldgen.planning.rrt_connect with the shared machinery of
// planning/base.py (trees, the stepping-stone pool, growing through the pool, the dense final check
// with the edge-cut retry) and the local planners of planning/local.py. Samples come from Python
// (the learned sampler) through the draw callback, a batch at a time.
//
// Lazy samples (where this search differs from the Python one, which takes checked samples from
// Sampler.sample_many): the callback returns the sampler's raw candidates (Sampler.raw_many:
// model decodes, uniform seeds), and a candidate is made a sample (the sampler's own refinement, refine
// projection iterations, then its check: limits and constraint) only when the search first uses it: a
// target when it is drawn, a pooled stepping stone when it is first tried. Most pooled samples are
// never tried, so they cost a decode and not a projection. The pool's distances of a raw candidate are
// those before its refinement (a few millimetres off): they only rank and filter stepping stones, and the
// motion to a stone is checked from the stone's refined place.
#include "core.hpp"

#include <algorithm>
#include <array>
#include <cstdlib>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>

namespace mgcore {

namespace {

using Clock = std::chrono::steady_clock;
constexpr double INF = std::numeric_limits<double>::infinity();
using States = Eigen::Map<const RowMat>;  // a motion's states (k, n), viewed in place

double dist2(const double* a, const double* b, int n) {
  double s = 0.0;
  for (int i = 0; i < n; ++i) s += (a[i] - b[i]) * (a[i] - b[i]);
  return s;
}

// Whether |a - b|^2 <= r2 (stops once past it).
bool close(const double* a, const double* b, int n, double r2) {
  double s = 0.0;
  for (int i = 0; i < n; ++i) {
    s += (a[i] - b[i]) * (a[i] - b[i]);
    if (s > r2) return false;
  }
  return true;
}

// Cubic cells of side `side` over the first K = min(n, 3) coordinates, spatially hashed into a fixed
// number of buckets of T (Teschner et al. 2003): the bucket of a cell holds everything in that cell
// (and, rarely, in cells hashed alike; callers compare true distances, so those cost a comparison and
// never change a result). No bounds, no rehashing; a lookup is an array index.
template <class T>
struct Cells {
  static constexpr int BITS = 11;
  using Cell = std::array<long, 3>;
  int K;
  double side;
  std::vector<std::vector<T>> buckets;

  Cells(int n, double side_) : K(std::min(n, 3)), side(side_), buckets(std::size_t{1} << BITS) {}
  Cell cell(const double* x) const {
    Cell c{0, 0, 0};
    for (int d = 0; d < K; ++d) c[d] = static_cast<long>(std::floor(x[d] / side));
    return c;
  }
  std::vector<T>& at(const Cell& c) {
    const unsigned long h = static_cast<unsigned long>(c[0]) * 73856093UL ^ static_cast<unsigned long>(c[1]) * 19349663UL ^
                            static_cast<unsigned long>(c[2]) * 83492791UL;
    return buckets[h & ((std::size_t{1} << BITS) - 1)];
  }
  const std::vector<T>& at(const Cell& c) const { return const_cast<Cells*>(this)->at(c); }
  // visit(cell) for the cells at Chebyshev distance s from c (s = 1: the 3^K - 1 around it), each once.
  template <class F>
  void shell(const Cell& c, long s, F&& visit) const {
    const long span[3] = {s, K > 1 ? s : 0, K > 2 ? s : 0};
    for (long i = -span[0]; i <= span[0]; ++i)
      for (long j = -span[1]; j <= span[1]; ++j)
        for (long k = -span[2]; k <= span[2]; ++k)
          if (std::max({std::labs(i), std::labs(j), std::labs(k)}) == s) visit(Cell{c[0] + i, c[1] + j, c[2] + k});
  }
  // visit(cell) for c, then the cells around it (3^K cells: everything within `side` of a point of c).
  template <class F>
  void around(const Cell& c, F&& visit) const {
    visit(c);
    shell(c, 1, visit);
  }
};

// An incremental k-d tree over rows of a row-major array (n columns) that its owner grows: leaves hold up
// to LEAF row ids; a full leaf splits at the middle of its widest coordinate. Exact nearest-neighbour
// queries: the near side first, the far side while the splitting plane is no farther than the best so far
// (ties go to the lowest id, as a linear scan's).
struct KdTree {
  static constexpr int LEAF = 12;
  struct Node {
    int dim = -1;  // -1: a leaf
    double split = 0.0;
    int child[2] = {-1, -1};
    std::vector<int> ids;
  };
  int n;
  std::vector<Node> nodes{1};

  explicit KdTree(int n_) : n(n_) {}
  void insert(int id, const double* data) {
    const double* x = data + static_cast<long>(id) * n;
    int at = 0;
    while (nodes[at].dim >= 0) at = nodes[at].child[x[nodes[at].dim] >= nodes[at].split];
    nodes[at].ids.push_back(id);
    if (static_cast<int>(nodes[at].ids.size()) > LEAF) divide(at, data);
  }
  void divide(int at, const double* data) {
    int dim = -1;
    double widest = 0.0, middle = 0.0;
    for (int d = 0; d < n; ++d) {
      double lo = INF, hi = -INF;
      for (int id : nodes[at].ids) lo = std::min(lo, data[static_cast<long>(id) * n + d]), hi = std::max(hi, data[static_cast<long>(id) * n + d]);
      if (hi - lo > widest) widest = hi - lo, dim = d, middle = lo + (hi - lo) / 2;
    }
    if (dim < 0) return;  // identical rows stay in one leaf
    const int first = static_cast<int>(nodes.size());
    nodes.resize(nodes.size() + 2);
    Node& node = nodes[at];
    node.dim = dim;
    node.split = middle;
    node.child[0] = first;
    node.child[1] = first + 1;
    for (int id : node.ids) nodes[first + (data[static_cast<long>(id) * n + dim] >= middle)].ids.push_back(id);
    std::vector<int>().swap(node.ids);
  }
  // The nearest row to x (n,) among those with keep[id], as (id, squared distance); (-1, inf) when none.
  std::pair<int, double> nearest(const double* x, const double* data, const std::vector<char>& keep) const {
    std::pair<int, double> best{-1, INF};
    offset.assign(n, 0.0);
    search(0, 0.0, x, data, keep, best);
    return best;
  }

  // Whether a row with keep[id] lies within squared distance r2 of x (n,): stops at the first found.
  bool any_within(const double* x, double r2, const double* data, const std::vector<char>& keep) const {
    offset.assign(n, 0.0);
    return within(0, 0.0, x, r2, data, keep);
  }

 private:
  mutable std::vector<double> offset;  // per coordinate: x's distance to the box of the node searched
  bool within(int at, double bound, const double* x, double r2, const double* data, const std::vector<char>& keep) const {
    const Node& node = nodes[at];
    if (node.dim < 0) {
      for (int id : node.ids)
        if (keep[id] && close(data + static_cast<long>(id) * n, x, n, r2)) return true;
      return false;
    }
    const double gap = x[node.dim] - node.split, before = offset[node.dim];
    if (within(node.child[gap >= 0], bound, x, r2, data, keep)) return true;
    const double far = bound - before * before + gap * gap;
    if (far > r2) return false;
    offset[node.dim] = gap;
    const bool found = within(node.child[gap < 0], far, x, r2, data, keep);
    offset[node.dim] = before;
    return found;
  }
  // bound: the squared distance from x to the node's box (Arya and Mount's incremental distance).
  void search(int at, double bound, const double* x, const double* data, const std::vector<char>& keep,
              std::pair<int, double>& best) const {
    const Node& node = nodes[at];
    if (node.dim < 0) {
      for (int id : node.ids) {
        if (!keep[id]) continue;
        const double d = dist2(data + static_cast<long>(id) * n, x, n);
        if (d < best.second || (d == best.second && id < best.first)) best = {id, d};
      }
      return;
    }
    const double gap = x[node.dim] - node.split, before = offset[node.dim];
    search(node.child[gap >= 0], bound, x, data, keep, best);
    const double far = bound - before * before + gap * gap;
    if (far > best.second) return;
    offset[node.dim] = gap;
    search(node.child[gap < 0], far, x, data, keep, best);
    offset[node.dim] = before;
  }
};

// Configurations with parent links; each edge is a straight segment, every node checked. Nearest-neighbour
// queries are exact (a k-d tree over the nodes, dead ones skipped).
struct Tree {
  int n;
  std::vector<double> q;
  std::vector<int> parent;
  std::vector<char> alive;
  // per node, how the edge into it was checked for collision at its planning-resolution states i (Local::segment_states):
  // 0 every state; s > 0 only where (i + 1) % s == 0 (coarse edges; Local::UNCHECKED: a loose part, none), the rest
  // left to Search::verify;
  // Local::DENSE: by the path check (dense edges)
  std::vector<int> coarse;
  KdTree index;

  explicit Tree(const Vec& root) : n(static_cast<int>(root.size())), index(n) { add(-1, root.data(), 0); }
  int size() const { return static_cast<int>(parent.size()); }
  const double* row(int i) const { return q.data() + static_cast<long>(i) * n; }
  int add(int from, const double* x, int checked_every) {
    q.insert(q.end(), x, x + n);
    parent.push_back(from);
    alive.push_back(1);
    coarse.push_back(checked_every);
    index.insert(size() - 1, q.data());
    return size() - 1;
  }
  int add_chain(int from, const RowMat& waypoints, int checked_every) {  // returns the last node
    for (int k = 0; k < waypoints.rows(); ++k) from = add(from, waypoints.row(k).data(), checked_every);
    return from;
  }
  int nearest(const double* x) const {  // the first node when none is alive, as a linear scan
    const int best = index.nearest(x, q.data(), alive).first;
    return best < 0 ? 0 : best;
  }
  std::vector<int> branch(int i) const {  // root .. i
    std::vector<int> out{i};
    while (parent[out.back()] >= 0) out.push_back(parent[out.back()]);
    std::reverse(out.begin(), out.end());
    return out;
  }
  void kill(int i) {  // node i and its descendants leave the nearest-neighbour queries
    alive[i] = 0;
    for (int j = i + 1; j < size(); ++j)
      if (parent[j] >= 0 && !alive[parent[j]]) alive[j] = 0;
  }
};

// Samples drawn but not yet in a tree: the stepping stones (planning/base.py SamplePool). The Python pool
// keeps each sample's distance to each tree; only whether it is within radius matters, so here each tree
// has a list of the free samples within radius of one of its nodes (what the stepping-stone queries scan)
// and the others in cubic cells of side radius over the first three coordinates (Cells), as are its
// synced nodes: a new node is compared with the samples of its cell and the 26 around it only, a new
// sample with the nodes of those cells (each comparison stops once past the radius). The same decisions
// as the Python pool, at a fraction of the distance work.
struct Pool {
  using Entry = std::pair<int, long>;  // (slot, the head count when the slot was filled)
  int n, capacity = 16384;
  double radius, radius2;
  RowMat q;
  std::vector<char> free, raw;  // raw: a candidate not yet made a sample (lazy samples)
  std::vector<long> born;       // per slot: the head count when filled (entries of an older sample are stale)
  std::vector<Entry> inside[2];
  std::vector<Cells<Entry>> outside;  // per tree
  std::vector<KdTree> nodes;         // each tree's synced nodes
  int synced[2] = {0, 0};
  long head = 0;

  Pool(int n_, double radius_, const std::vector<Tree>& trees)
      : n(n_), radius(radius_), radius2(radius_ * radius_), q(16384, n_),
        outside(2, Cells<Entry>(n_, radius_)), nodes(2, KdTree(n_)) {
    free.assign(capacity, 0);
    raw.assign(capacity, 0);
    born.assign(capacity, -1);
    for (int k = 0; k < 2; ++k) sync_nodes(k, trees[k]);
  }
  void sync_nodes(int k, const Tree& t) {
    for (int i = synced[k]; i < t.size(); ++i) nodes[k].insert(i, t.q.data());
    synced[k] = t.size();
  }
  bool near_node(const double* x, int k, const Tree& t) const { return nodes[k].any_within(x, radius2, t.q.data(), t.alive); }
  bool current(const Entry& e) const { return free[e.first] && born[e.first] == e.second; }
  void add(const double* x, const std::vector<Tree>& trees, bool unrefined = false) {
    const int slot = static_cast<int>(head % capacity);
    std::copy(x, x + n, q.row(slot).data());
    free[slot] = 1;
    raw[slot] = unrefined;
    born[slot] = head;
    for (int k = 0; k < 2; ++k) {
      if (near_node(x, k, trees[k])) inside[k].emplace_back(slot, head);
      else outside[k].at(outside[k].cell(x)).emplace_back(slot, head);
    }
    ++head;
  }
  void add_raw(const RowMat& x, const std::vector<Tree>& trees) {
    for (int r = 0; r < x.rows(); ++r) add(x.row(r).data(), trees, true);
  }
  // Move the samples within radius of tree k's new nodes to its inside list; drop used samples.
  void refresh(int k, const Tree& t) {
    std::vector<Entry>& in = inside[k];
    std::size_t kept = 0;
    for (const Entry& e : in)
      if (current(e)) in[kept++] = e;
    in.resize(kept);
    for (int i = synced[k]; i < t.size(); ++i) {
      if (!t.alive[i]) continue;
      const double* node = t.row(i);
      outside[k].around(outside[k].cell(node), [&](const Cells<Entry>::Cell& c) {
        std::vector<Entry>& out = outside[k].at(c);
        std::size_t left = 0;
        for (const Entry& e : out) {
          if (!current(e)) continue;
          if (close(q.row(e.first).data(), node, n, radius2)) in.push_back(e);
          else out[left++] = e;
        }
        out.resize(left);
      });
    }
    sync_nodes(k, t);
  }
  bool reachable(int k, const Tree& t) {
    refresh(k, t);
    return !inside[k].empty();
  }
  // The slots of the `count` samples inside tree k nearest to target (nearest first, ties by slot), closer than `than`.
  std::vector<int> closest(int k, const Tree& t, const double* target, int count, double than) {
    refresh(k, t);
    std::vector<std::pair<double, int>>& near = nearest_buffer;  // sorted, at most count
    near.clear();
    const double limit = than * than;
    for (const Entry& e : inside[k]) {
      const double d = dist2(q.row(e.first).data(), target, n);
      if (d >= limit) continue;
      const std::pair<double, int> item{d, e.first};
      if (static_cast<int>(near.size()) == count) {
        if (count == 0 || !(item < near.back())) continue;
        near.pop_back();
      }
      near.insert(std::upper_bound(near.begin(), near.end(), item), item);
    }
    std::vector<int> out;
    for (const auto& item : near) out.push_back(item.second);
    return out;
  }
  std::vector<std::pair<double, int>> nearest_buffer;
};

// The local planners of planning/local.py: interpolate, project, auto, direct.
struct Local {
  Space& space;
  double resolution, step;
  bool partial, stones, walks;
  int kind;  // 0 auto, 1 interpolate, 2 project, 3 direct
  // Coarse-first edge checks: a motion's states i (segment_states) are checked for collision only where
  // (i + 1) % stride == 0 and at the state it ends at when that becomes a node (limits, constraint and
  // inequalities at every state); Search::verify checks the others when the edge lies on a candidate path.
  // 1: every state (eager); UNCHECKED: the record of a loose part (made()).
  static constexpr int UNCHECKED = std::numeric_limits<int>::max();
  int stride = 1;
  // Dense edges (PlannerSettings::dense_edges): a motion is kept only when it passes the path check
  // (Space::validate_path of its two ends: every dense state, certified sweeps), after a pre-check of its coarse
  // states (coarse_valid: every stride-th and its end; every test, bisection order) that finds most blocked motions
  // for a fraction of the dense states. Its edge record (Tree::coarse) is DENSE: a path of such edges needs no further check.
  bool dense = false;
  static constexpr int DENSE = -1;
  bool loose = false;  // the latest straight motion kept a part whose own states are not those checked
  long projections = 0;
  double precision, damping, max_step;  // a projected walk's projections (PlannerSettings)
  int max_iters;

  Local(Space& s, const PlannerSettings& p)
      : space(s), resolution(p.resolution), step(p.step), partial(p.partial), precision(p.precision),
        damping(p.damping), max_step(p.max_step), max_iters(p.max_iters) {
    static const char* names[4] = {"auto", "interpolate", "project", "direct"};
    kind = static_cast<int>(std::find(names, names + 4, p.local) - names);
    if (kind == 4) throw std::runtime_error("unknown local planner '" + p.local + "'; known: auto, interpolate, project, direct");
    stones = kind == 0 || kind == 1;
    walks = kind == 0 || kind == 2;
  }
  int n() const { return space.n(); }

  // The states every resolution along a -> b, a excluded, b included (k, n): a view of a buffer reused by the
  // next call (no allocation per motion once it has grown).
  States segment_states(const double* a, const double* b) {
    Eigen::Map<const Vec> va(a, n()), vb(b, n());
    const int k = std::max(1, static_cast<int>(std::ceil((vb - va).norm() / resolution)));
    segment_buffer.resize(static_cast<std::size_t>(k) * n());
    Eigen::Map<RowMat> out(segment_buffer.data(), k, n());
    for (int i = 1; i <= k; ++i) out.row(i - 1) = (va + (vb - va) * (static_cast<double>(i) / k)).transpose();
    return States(segment_buffer.data(), k, n());
  }
  std::vector<double> segment_buffer;
  int steps(const double* a, const double* b) const {  // segment_states' k
    return std::max(1, static_cast<int>(std::ceil((Eigen::Map<const Vec>(b, n()) - Eigen::Map<const Vec>(a, n())).norm() / resolution)));
  }
  // Of a motion's k states (the last a node when node): whether state i is checked for collision
  // (coarse()), how many are (sparse()) and which is the j-th of those (sparse_state()).
  bool coarse(int i, int k, bool node) const { return (i + 1) % stride == 0 || (node && i == k - 1); }
  int sparse(int k, bool node) const { return k / stride + (node && k % stride != 0); }
  int sparse_state(int j, int k) const { return std::min((j + 1) * stride - 1, k - 1); }
  // The edge record (Tree::coarse) of the motion just made.
  int made() const { return dense ? DENSE : stride == 1 ? 0 : loose ? UNCHECKED : stride; }

  // Leading valid rows of a motion's states, in order. Coarse (stride > 1): limits and constraint at every
  // state, then collisions at the coarse states and at the last valid row (the node the motion ends at); a
  // collision keeps the rows up to the last coarse state found free.
  int prefix(const States& s, bool last_is_node) {
    const int k = static_cast<int>(s.rows());
    if (stride == 1) return space.valid_prefix(s.data(), k, last_is_node, true);
    const int count = space.valid_prefix(s.data(), k, last_is_node, false), first = space.stop;
    int kept = 0;
    for (int i = 0; i < count; ++i) {
      if (!coarse(i, count, true)) continue;
      if (!space.collision_free(s.row(i).data())) {
        if (first != VALID) --space.counts.stopped[first];  // the motion stopped earlier, at this collision
        stopped(COLLISION);
        return kept;
      }
      kept = i + 1;
    }
    return count;
  }
  // Whether the first k states of a motion (the last of them a node when last_is_node) are all valid:
  // limits and constraint in order, then collisions (at the coarse states) in bisection order (middle
  // first: a blocked motion is found blocked after fewer checks than scanning from its start).
  // first_blocked: the coarse states are visited in bisection order, each tested in the validity rule's
  // order (limits, constraint, inequalities, collision), then the others' limits and constraint: the same
  // verdict after fewer residuals when a collision blocks the motion, but stop names the first failure
  // found that way (the walks read stop to choose what to do next, so they keep the order above).
  bool all_valid(const States& s, int k, bool last_is_node, bool first_blocked = false) {
    if (first_blocked && !space.batched()) {
      if (!coarse_valid(s, k, last_is_node)) return false;
      const double inner = 1.0 - space.margin();
      auto limit = [&](int i) { return last_is_node && i == k - 1 ? 1.0 : inner; };
      return stride == 1 || bisect(k, [&](int i) {
        return coarse(i, k, last_is_node) ? VALID : space.code(s.row(i).data(), limit(i), false, true);
      });
    }
    if (space.valid_prefix(s.data(), k, last_is_node, false) != k) return false;
    return bisect(sparse(k, last_is_node), [&](int j) { return space.collision_free(s.row(sparse_state(j, k)).data()) ? VALID : COLLISION; });
  }
  // Whether the coarse states of a motion's first k states pass every test (limits, constraint, inequalities,
  // collision), in bisection order.
  bool coarse_valid(const States& s, int k, bool last_is_node) {
    const double inner = 1.0 - space.margin();
    return bisect(sparse(k, last_is_node), [&](int j) {
      const int i = sparse_state(j, k);
      return space.code(s.row(i).data(), last_is_node && i == k - 1 ? 1.0 : inner, true, true);
    });
  }
  // test(i) -> Reason of state i for i in [0, k), middle first, then the middles of the halves (breadth
  // first); the first failure sets stop and ends it.
  template <class Test>
  bool bisect(int k, const Test& test) {
    spans.assign(1, {0, k - 1});
    for (std::size_t next = 0; next < spans.size(); ++next) {
      const auto [lo, hi] = spans[next];
      if (lo > hi) continue;
      const int mid = (lo + hi) / 2;
      const int c = test(mid);
      if (c != VALID) return stopped(c);
      spans.push_back({lo, mid - 1});
      spans.push_back({mid + 1, hi});
    }
    space.stop = VALID;
    return true;
  }
  std::vector<std::array<int, 2>> spans;  // bisect's queue, kept between calls
  // A motion stopped for `reason` (the space's stop and its count): false.
  bool stopped(int reason) {
    space.stop = reason;
    ++space.counts.stopped[reason];
    return false;
  }
  bool whole(const double* a, const double* b) {
    if (dense) return dense_valid(a, b);
    const States s = segment_states(a, b);
    return all_valid(s, static_cast<int>(s.rows()), true);
  }

  // Dense edges: whether the motion a -> b (b a node) passes the pre-check, then the path check; sets stop.
  bool dense_valid(const double* a, const double* b) {
    const States s = segment_states(a, b);
    if (!coarse_valid(s, static_cast<int>(s.rows()), true)) return false;
    ends_buffer.resize(2 * static_cast<std::size_t>(n()));
    std::copy(a, a + n(), ends_buffer.begin());
    std::copy(b, b + n(), ends_buffer.begin() + n());
    const PathCheck c = space.validate_path(ends_buffer.data(), 2, true);
    if (!c.valid) return stopped(c.reason);
    space.stop = VALID;
    return true;
  }
  std::vector<double> ends_buffer;

  // Dense edges, straight(): the motion a -> end, else (partial) its planning-resolution states up to the first that
  // fails the pre-check in order when the part up to there passes the path check; stop: the whole motion's failure.
  std::pair<RowMat, bool> dense_straight(const double* a, const Vec& end, bool reach) {
    loose = false;
    if (dense_valid(a, end.data())) return {end.transpose(), reach};
    const int reason = space.stop;
    if (!partial) return {none(), false};
    const States s = segment_states(a, end.data());
    const int k = static_cast<int>(s.rows());
    const double inner = 1.0 - space.margin();
    int kept = 0;
    for (int i = stride - 1; i < k - 1 && space.code(s.row(i).data(), inner, true, true) == VALID; i += stride) kept = i + 1;
    const Vec last = kept ? Vec(s.row(kept - 1).transpose()) : Vec();
    const bool valid = kept && dense_valid(a, last.data());
    space.stop = reason;
    return valid ? std::make_pair(RowMat(last.transpose()), false) : std::make_pair(none(), false);
  }
  RowMat none() const { return RowMat(0, n()); }

  std::pair<RowMat, bool> straight(const double* a, const double* b, double max_distance) {
    Eigen::Map<const Vec> va(a, n()), vb(b, n());
    const double distance = (vb - va).norm();
    const bool reach = distance <= max_distance;
    const Vec end = reach ? Vec(vb) : Vec(va + (vb - va) * (max_distance / distance));
    if (dense) return dense_straight(a, end, reach);
    const States s = segment_states(a, end.data());
    const int count = prefix(s, reach);
    loose = false;
    if (count == s.rows()) return {end.transpose(), reach};
    if (!partial || !count) return {none(), false};
    loose = stride > 1 && steps(a, s.row(count - 1).data()) != count;  // the kept part spaced otherwise
    return {s.row(count - 1), false};
  }

  // q (n) projected in place onto the manifold to precision x the smallest tolerance (a walk's step, a relaxed
  // waypoint), counted; whether it converged.
  bool onto_manifold(double* q) {
    ++projections;
    return space.project(q, precision * space.tolerance().minCoeff(), max_iters, damping, max_step).converged;
  }

  std::pair<RowMat, bool> walk(const double* a, const double* b, double max_distance, bool creep = true) {
    loose = false;
    const int nn = n();
    Eigen::Map<const Vec> vb(b, nn);
    std::vector<Vec> waypoints;
    Vec q = Eigen::Map<const Vec>(a, nn), target(nn);
    double travelled = 0.0, length = step;
    auto result = [&](bool reached) {
      RowMat out(waypoints.size(), nn);
      for (std::size_t i = 0; i < waypoints.size(); ++i) out.row(i) = waypoints[i].transpose();
      return std::make_pair(out, reached);
    };
    while (travelled < max_distance) {
      const double gap = (vb - q).norm();
      if (gap <= length && space.violation(b) <= 1.0) {
        if (whole(q.data(), b)) {
          waypoints.push_back(vb);
          return result(true);
        }
        if (!creep && space.stop == COLLISION) break;
      } else {
        target = q + (vb - q) * std::min(1.0, length / std::max(gap, 1e-12));
        const bool converged = onto_manifold(target.data());
        const double moved = (target - q).norm();
        if (!converged || moved > 2 * length || moved < 1e-9 || (vb - target).norm() >= gap) break;
        if (whole(q.data(), target.data())) {
          waypoints.push_back(target);
          travelled += moved;
          q = target;
          length = std::min(step, 2 * length);
          continue;
        }
        if (!creep && space.stop == COLLISION) break;
      }
      if (length / 2 < resolution) break;
      length /= 2;
    }
    return result(false);
  }

  std::pair<RowMat, bool> steer(const double* a, const double* b, double max_distance) {
    if (kind == 2) return walk(a, b, max_distance);
    auto out = straight(a, b, max_distance);
    if (kind != 0 || out.second || space.stop != CONSTRAINT) return out;
    return walk(a, b, max_distance);
  }

  // Waypoints ending at b when the whole motion is valid (reached), else reached = false.
  std::pair<RowMat, bool> connect(const double* a, const double* b) {
    if (kind == 2) return walk(a, b, INF);
    auto out = straight(a, b, INF);
    if (kind == 0 && !out.second && space.stop == CONSTRAINT) out = walk(a, b, INF, false);
    return out;
  }

  // Whether the straight segment start -> end (a pooled sample, not yet checked for collision) is valid
  // all along (planning/local.py first_valid, one candidate). The end is checked first: a colliding
  // sample costs one check. sample: the end passed the limits and the constraint already (a sample made
  // just now), so only its collisions are left.
  bool reaches(const double* start, const double* end, bool sample) {
    loose = false;
    const int c = sample ? (space.collision_free(end) ? VALID : COLLISION) : space.code(end, 1.0, true, true);
    if (c != VALID) return stopped(c);
    if (dense) return dense_valid(start, end);
    const States s = segment_states(start, end);
    return all_valid(s, static_cast<int>(s.rows()) - 1, false, true);  // the end is checked
  }
};

struct Search {
  Space& space;
  const Draw& draw;
  PlannerSettings s;
  Local local;
  Clock::time_point deadline;
  std::vector<Tree> trees;
  std::unique_ptr<Pool> pool;
  PlanOutput out;
  RowMat targets;
  int next = 0;

  Search(Space& sp, const Draw& d, const PlannerSettings& st, double time_limit)
      : space(sp), draw(d), s(st), local(sp, st),
        deadline(Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(time_limit))) {}

  bool time_left() const { return Clock::now() < deadline; }

  RowMat draw_many(int count) {
    RowMat rows = draw(count);
    if (rows.rows() != count || rows.cols() != space.n())
      throw std::runtime_error("the sampler callback returned an array of the wrong shape");
    out.samples += count;
    return rows;
  }
  // A raw candidate made a sample in place (lazy samples): the sampler's refinement (refine iterations of
  // constraints.project with its default tolerance, damping and step, PlannerSettings) and its check (limits,
  // constraint; collisions are the search's, as for every state it keeps). Whether it is a sample.
  bool make_sample(double* q) {
    ++out.refined;
    if (s.refine > 0) space.project(q, s.tol, s.refine, s.damping, s.max_step);
    const bool ok = space.code(q, 1.0, false, true) == VALID;
    out.accepted += ok;
    return ok;
  }
  Vec target() {
    while (true) {
      if (next >= targets.rows()) {
        targets = draw_many(s.target_batch);
        next = 0;
      }
      double* q = targets.row(next++).data();
      if (make_sample(q) || !time_left()) return Eigen::Map<const Vec>(q, space.n());
    }
  }

  // Check the coarse edges of a candidate path for collision at the planning-resolution states their
  // search skipped (path order; each edge's in bisection order). A colliding edge is cut from its tree:
  // its node gets another parent when it can (reattach), else it and its subtree leave the search; and the
  // search checks every state of its motions from then on: an obstacle thinner than the coarse spacing
  // would let the trees through it again and again (talos reach at stride 2, seeds 7 and 24: 32 and 24 cuts
  // without this, 1 with it). True when every edge passed.
  bool verify(const std::vector<std::pair<int, int>>& edges) {
    for (const auto& [k, child] : edges) {
      Tree& tree = trees[k];
      const int every = tree.coarse[child];
      if (every <= 0) continue;  // checked at every state (0) or by the path check (Local::DENSE)
      const States states = local.segment_states(tree.row(tree.parent[child]), tree.row(child));
      const bool free = local.bisect(static_cast<int>(states.rows()) - 1, [&](int i) {  // the child, a node, was checked
        if ((i + 1) % every == 0) return VALID;
        ++out.verified_states;
        return space.collision_free(states.row(i).data()) ? VALID : COLLISION;
      });
      if (free) {
        tree.coarse[child] = 0;
        continue;
      }
      ++out.cut_edges;
      local.stride = 1;
      if (reattach(k, child)) ++out.reattached;
      else tree.kill(child);
      return false;
    }
    return true;
  }

  // Give node `child` of tree k, whose edge was found colliding, a new parent: its nearest older node within
  // range (the old parent excepted; an older node is never in its subtree, and parents stay before their
  // children, which Tree::kill relies on), when the motion from there is valid at every state. Its subtree
  // then stays in the search. Whether it did.
  bool reattach(int k, int child) {
    Tree& tree = trees[k];
    std::vector<char>& keep = keep_buffer;
    keep.assign(tree.alive.begin(), tree.alive.begin() + child);
    keep.resize(tree.size(), 0);
    keep[tree.parent[child]] = 0;
    const auto [near, d2] = tree.index.nearest(tree.row(child), tree.q.data(), keep);
    if (near < 0 || d2 > s.range * s.range) return false;
    const int stride = local.stride;
    local.stride = 1;
    const bool valid = local.whole(tree.row(near), tree.row(child));
    local.stride = stride;
    if (!valid) return false;
    tree.parent[child] = near;
    tree.coarse[child] = 0;
    return true;
  }
  std::vector<char> keep_buffer;

  // A path (K, n) that passed the dense check, or 0 rows; a failing edge is cut from its tree.
  bool finish(const RowMat& waypoints, const std::vector<std::pair<int, int>>& edges) {
    if (!verify(edges)) return false;
    if (std::all_of(edges.begin(), edges.end(), [&](const auto& e) { return trees[e.first].coarse[e.second] == Local::DENSE; })) {
      out.path = waypoints;  // every edge passed the path check when it was made
      return true;
    }
    const PathCheck c = space.validate_path(waypoints.data(), static_cast<int>(waypoints.rows()), true);
    if (c.valid) {
      out.path = waypoints;
      return true;
    }
    ++out.rejected;
    const auto& e = edges[c.segment];
    trees[e.first].kill(e.second);
    return false;
  }

  bool direct(const Vec& start, const Vec& goal) {
    auto w = local.connect(start.data(), goal.data());
    if (!w.second) return false;
    RowMat path(w.first.rows() + 1, space.n());
    path.row(0) = start.transpose();
    path.bottomRows(w.first.rows()) = w.first;
    const PathCheck c = space.validate_path(path.data(), static_cast<int>(path.rows()), true);
    out.rejected += !c.valid;
    if (c.valid) out.path = path;
    return c.valid;
  }

  void start_pool() {
    if (!local.stones) return;
    pool.reset(new Pool(space.n(), s.reach > 0 ? std::min(s.reach, s.range) : s.range, trees));
    for (int i = 0; i < s.pool; i += s.pool_batch) {
      if (Clock::now() > deadline) break;
      pool->add_raw(draw_many(s.pool_batch), trees);
    }
  }

  // Extend tree k toward a target out of range through the pool (base.py Planner._far).
  int far(int k, int near, const double* target, double than = INF) {
    Tree& tree = trees[k];
    const std::vector<int> slots = pool->closest(k, tree, target, s.candidates, than);
    if (slots.empty()) {
      if (pool->reachable(k, tree)) return -1;
      ++out.out_of_reach;
      if (!local.walks) return -1;
      auto w = local.walk(tree.row(near), target, s.range);
      return w.first.rows() ? tree.add_chain(near, w.first, local.made()) : -1;
    }
    // the first candidate reached in a straight line from its nearest node becomes a node (a raw one is
    // made a sample first); the tried ones leave the pool
    for (int slot : slots) {
      pool->free[slot] = 0;
      double* stone = pool->q.row(slot).data();
      const bool made = pool->raw[slot];
      if (made && !make_sample(stone)) continue;
      pool->raw[slot] = 0;
      const int node = tree.nearest(stone);
      if (local.reaches(tree.row(node), stone, made)) return tree.add(node, stone, local.made());
    }
    return -1;
  }

  // Extend tree k toward target from its nearest node (base.py Planner._grow).
  int grow(int k, const Vec& target) {
    Tree& tree = trees[k];
    const int near = tree.nearest(target.data());
    if (!pool || (target - Eigen::Map<const Vec>(tree.row(near), space.n())).norm() <= s.range) {
      auto w = local.steer(tree.row(near), target.data(), s.range);
      return w.first.rows() ? tree.add_chain(near, w.first, local.made()) : -1;
    }
    pool->add(target.data(), trees);
    const int made = far(k, near, target.data());
    if (made < 0 && !pool->reachable(k, tree)) pool->add_raw(draw_many(s.pool_batch), trees);
    return made;
  }

  // Grow tree k toward target until it reaches it (that node) or is stuck (-1) (rrt_connect.py _connect).
  int connect(int k, const Vec& target) {
    Tree& tree = trees[k];
    while (time_left()) {
      int node = tree.nearest(target.data());
      const double gap = (target - Eigen::Map<const Vec>(tree.row(node), space.n())).norm();
      if (pool && gap > s.range) {
        if (far(k, node, target.data(), gap) < 0) return -1;
        continue;
      }
      auto w = local.steer(tree.row(node), target.data(), s.range);
      if (!w.first.rows()) return -1;
      node = tree.add_chain(node, w.first, local.made());
      if (w.second) return node;
    }
    return -1;
  }

  // root(0) .. node i == node j .. root(1), densely checked.
  bool join(int i, int j) {
    const std::vector<int> pa = trees[0].branch(i), pb = trees[1].branch(j);
    const int nn = space.n();
    RowMat waypoints(pa.size() + pb.size() - 1, nn);
    std::vector<std::pair<int, int>> edges;
    int r = 0;
    for (std::size_t t = 0; t < pa.size(); ++t) {
      waypoints.row(r++) = Eigen::Map<const Eigen::RowVectorXd>(trees[0].row(pa[t]), nn);
      if (t) edges.emplace_back(0, pa[t]);
    }
    for (int t = static_cast<int>(pb.size()) - 2; t >= 0; --t) {
      waypoints.row(r++) = Eigen::Map<const Eigen::RowVectorXd>(trees[1].row(pb[t]), nn);
      edges.emplace_back(1, pb[t + 1]);
    }
    return finish(waypoints, edges);
  }

  // Shortcuts (settings.shortcut attempts while time is left; planning/smoothing.py is the same in Python): attempt
  // a = 1, 2, ... joins the points A and B at arc-length fractions u < v of the current path, (u, v) the sorted
  // (a * ALPHA[0], a * ALPHA[1]) mod 1 (an additive recurrence: evenly spread pairs, no random state), by a straight
  // motion, else (the chord leaves the manifold) by a projected walk. The new stretch, from the waypoint before A
  // to the one after B, replaces the old one only when it is shorter and passes the path check (Space::validate_path:
  // every dense state, the same check as any path's; the new motion is checked at the planning resolution first, as
  // the search checks its motions), so the path stays valid at every step.
  static constexpr double ALPHA[2] = {0.7548776662466927, 0.5698402909980532};
  void shorten() {
    RowMat& path = out.path;
    const int nn = space.n();
    out.found_length = length(path);
    local.dense = false;
    for (int a = 1; a <= s.shortcut && path.rows() > 2 && time_left(); ++a) {
      std::vector<double> cum(path.rows(), 0.0);
      for (long k = 1; k < path.rows(); ++k) cum[k] = cum[k - 1] + (path.row(k) - path.row(k - 1)).norm();
      double u = std::fmod(a * ALPHA[0], 1.0), v = std::fmod(a * ALPHA[1], 1.0);
      if (u > v) std::swap(u, v);
      const double total = cum.back(), from = u * total, to = v * total;
      const long i = segment_at(cum, from), j = segment_at(cum, to);
      if (i == j) continue;  // one straight segment already
      const Vec A = point_at(path, cum, i, from), B = point_at(path, cum, j, to);
      if ((B - A).norm() >= to - from - 1e-9) continue;
      // the new motion at the planning resolution first (most attempts end there), then densely, then the flanks
      RowMat piece = B.transpose();
      const States chord = local.segment_states(A.data(), B.data());
      if (!local.all_valid(chord, static_cast<int>(chord.rows()), true, true)) {
        if (space.stop != CONSTRAINT || !local.walks) continue;
        auto w = local.walk(A.data(), B.data(), INF, false);
        if (!w.second || length(A, w.first) >= to - from - 1e-9) continue;
        piece = w.first;
      }
      RowMat motion(piece.rows() + 1, nn);
      motion << A.transpose(), piece;
      if (!space.validate_path(motion.data(), static_cast<int>(motion.rows()), true).valid ||
          !motions_valid(Vec(path.row(i).transpose()), A) || !motions_valid(B, Vec(path.row(j + 1).transpose())))
        continue;
      const RowMat stretch = stretch_of(path, i, A, piece, j);
      RowMat shorter(i + stretch.rows() + (path.rows() - j - 2), nn);
      shorter.topRows(i) = path.topRows(i);
      shorter.middleRows(i, stretch.rows()) = stretch;
      shorter.bottomRows(path.rows() - j - 2) = path.bottomRows(path.rows() - j - 2);
      path = drop_repeats(shorter);
      ++out.shortcuts;
    }
    if (s.shortcut > 0) relax();
  }

  // Relaxation (after the shortcuts, while time is left; planning/smoothing.py relax is the same in Python): each
  // sweep pulls every inner waypoint toward the midpoint of its neighbours, half way, else a quarter, else an eighth,
  // projected onto the manifold, and keeps the move when it shortens the two motions at the waypoint and the motions
  // through the point pulled twice as far pass the path check. That probe keeps the path off the obstacles it is
  // pulled against (a taut path would graze them between the dense check's states, where a trajectory's samples
  // land), and the motions through the kept point lie between two checked ones: the whole path is checked once at
  // the end, and should it fail, the path as shortened stays. Shortcuts join far points; relaxation pulls the path
  // taut where no straight or walked shortcut fits (a closed chain's detours). Sweeps stop after one that shortens
  // the path by less than RELAX_GAIN of its length, or after RELAX_SWEEPS.
  static constexpr double RELAX_GAIN = 0.01;
  static constexpr int RELAX_SWEEPS = 30;
  void relax() {
    RowMat taut = out.path;
    long moves = 0;
    for (int sweep = 0; sweep < RELAX_SWEEPS && taut.rows() > 2 && time_left(); ++sweep) {
      double gained = 0.0;
      for (long i = 1; i + 1 < taut.rows(); ++i) {
        const Vec a = taut.row(i - 1).transpose(), q = taut.row(i).transpose(), b = taut.row(i + 1).transpose();
        const Vec pull = 0.5 * (a + b) - q;
        const double before = (q - a).norm() + (b - q).norm();
        for (double share = 0.5; share > 0.1; share /= 2) {
          Vec m = q + share * pull, probe = q + 2 * share * pull;
          if (!local.onto_manifold(m.data())) continue;
          const double after = (m - a).norm() + (b - m).norm();
          if (after >= before || !local.onto_manifold(probe.data()) || !motions_valid(a, probe, b)) continue;
          taut.row(i) = m.transpose();
          gained += before - after;
          ++moves;
          break;
        }
      }
      if (gained < RELAX_GAIN * length(taut)) break;
    }
    if (!space.validate_path(taut.data(), static_cast<int>(taut.rows()), true).valid) return;  // as shortened
    out.path = drop_repeats(taut);
    out.relaxed = moves;
  }
  // Whether the straight motions through points (n each, in order) pass the path check.
  template <class... Points>
  bool motions_valid(const Points&... points) {
    RowMat rows(sizeof...(points), space.n());
    long r = 0;
    ((rows.row(r++) = points.transpose()), ...);
    return space.validate_path(rows.data(), static_cast<int>(rows.rows()), true).valid;
  }
  static double length(const RowMat& p) {
    double l = 0.0;
    for (long k = 1; k < p.rows(); ++k) l += (p.row(k) - p.row(k - 1)).norm();
    return l;
  }
  static double length(const Vec& a, const RowMat& rest) {  // a, then rest's rows
    return (rest.row(0).transpose() - a).norm() + length(rest);
  }
  // The segment k (path rows k, k + 1) holding arc length t, cum the rows' arc lengths (K,).
  static long segment_at(const std::vector<double>& cum, double t) {
    const long k = std::upper_bound(cum.begin(), cum.end(), t) - cum.begin() - 1;
    return std::clamp<long>(k, 0, static_cast<long>(cum.size()) - 2);
  }
  static Vec point_at(const RowMat& path, const std::vector<double>& cum, long k, double t) {
    const double span = cum[k + 1] - cum[k], f = span > 0 ? (t - cum[k]) / span : 0.0;
    return (path.row(k) + (path.row(k + 1) - path.row(k)) * f).transpose();
  }
  // Rows path[i], A, piece (ending at B), path[j + 1].
  static RowMat stretch_of(const RowMat& path, long i, const Vec& A, const RowMat& piece, long j) {
    RowMat out(piece.rows() + 3, path.cols());
    out.row(0) = path.row(i);
    out.row(1) = A.transpose();
    out.middleRows(2, piece.rows()) = piece;
    out.row(out.rows() - 1) = path.row(j + 1);
    return out;
  }
  // path without rows equal to the one before them (a shortcut point on a waypoint).
  static RowMat drop_repeats(const RowMat& path) {
    std::vector<long> keep{0};
    for (long k = 1; k < path.rows(); ++k)
      if ((path.row(k).array() != path.row(keep.back()).array()).any()) keep.push_back(k);
    RowMat out(keep.size(), path.cols());
    for (std::size_t r = 0; r < keep.size(); ++r) out.row(r) = path.row(keep[r]);
    return out;
  }

  void run(const Vec& start, const Vec& goal) {
    // the direct motion is checked at every state (a coarse direct walk would cross obstacles), or with dense edges
    // at every edge_stride-th (the path check follows); not in a tree, its progress is dropped when it fails
    if (s.dense_edges) local.stride = s.edge_stride;
    if (direct(start, goal)) return;
    local.stride = s.edge_stride;
    local.dense = s.dense_edges;
    trees.emplace_back(start);
    trees.emplace_back(goal);
    start_pool();
    while (time_left()) {
      ++out.iterations;
      const int side = static_cast<int>(out.iterations % 2);
      const int made = grow(side, target());
      if (made < 0) continue;
      const Vec reached = Eigen::Map<const Vec>(trees[side].row(made), space.n());
      const int joint = connect(1 - side, reached);
      if (joint < 0) continue;
      if (side == 0 ? join(made, joint) : join(joint, made)) return;
    }
  }
};

}  // namespace

PlanOutput rrt_connect(Space& space, const Vec& start, const Vec& goal, const Draw& draw,
                       const PlannerSettings& settings, double time_limit) {
  if (start.size() != space.n() || goal.size() != space.n())
    throw std::runtime_error("start and goal must have one value per active coordinate");
  Search search(space, draw, settings, time_limit);
  search.run(start, goal);
  if (search.out.path.rows()) search.shorten();
  for (const Tree& t : search.trees) search.out.nodes.push_back(t.size());
  search.out.projections = search.local.projections;
  if (!search.out.path.rows()) search.out.path = RowMat(0, space.n());
  return search.out;
}

NearestAnswers nearest_queries(const RowMat& points, const std::vector<char>& alive, const RowMat& queries,
                               double radius) {
  const int n = static_cast<int>(points.cols());
  if (queries.cols() != n || static_cast<long>(alive.size()) != points.rows())
    throw std::runtime_error("points (N, n), alive (N,) and queries (Q, n) must agree");
  KdTree index(n);
  for (int i = 0; i < points.rows(); ++i) index.insert(i, points.data());
  NearestAnswers out;
  for (int r = 0; r < queries.rows(); ++r) {
    const double* x = queries.row(r).data();
    out.nearest.push_back(index.nearest(x, points.data(), alive).first);
    out.within.push_back(index.any_within(x, radius * radius, points.data(), alive));
  }
  return out;
}

}  // namespace mgcore
