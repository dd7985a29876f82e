// Node types and the context a node cooks in. Each node type registers one NodeTypeInfo: its
// parameter table, its role in a chain and a factory. Nodes never read JSON: the evaluator hands
// them evaluated parameters and the object's particles.
#pragma once
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "engine/collider.h"
#include "engine/params.h"
#include "engine/particles.h"

namespace grains {

// What the evaluator knows of the current moment.
struct TimeInfo {
  double fps = 24;
  int substeps = 1;       // substeps this frame is being split into now (error control may raise it)
  int base_substeps = 1;  // the solver's `substeps` parameter: stiffness fractions count these
  bool stabilize = false;  // the first substep after error control refined the step
  int frame = 1;      // 1-based frame being computed (ends at time frame / fps)
  int substep = 0;    // 0-based substep within the frame
  double dt = 0;      // substep length (s)
  double st = 0;      // simulation time at the start of this substep (s)
};

// Momentum the particles gave one collider during the current frame (two-way coupling, help page
// "Enable Collision Feedback"): the opposite of what the collider gave them. Nodes add to it;
// the evaluator clears it at the start of each frame and FrameWriter writes it as the frame's
// mean force and torque (impulse / frame length) to colliders.csv.
struct ColliderFeedback {
  Vec3 impulse;          // N s
  Vec3 angular_impulse;  // N m s, about the collider's translate (its pose's origin)
};

// The most points a run may hold (grains run --max-points): an emission that would pass it is
// refused, with the numbers, before anything is allocated. A point costs about kBytesPerPoint
// while the grains solve it (BENCHMARKS.md measures 517-730 B a grain).
constexpr size_t kDefaultMaxPoints = 20000000;
constexpr size_t kBytesPerPoint = 600;

// An emission past the point budget: bad input (exit 2).
struct BudgetError : std::runtime_error {
  using std::runtime_error::runtime_error;
};
// Throws BudgetError when `adding` more points on top of `have` would pass `max`; `what` says
// what was being made ("a box of 1000 x 1000 x 1000 grains").
void check_point_budget(const std::string& node, double adding, size_t have, size_t max,
                        const std::string& what);

struct CookContext {
  ParticleStore& pts;
  const ParamSet& params;
  const TimeInfo& time;
  const std::vector<ColliderState>& colliders;  // the solver's colliders at this substep
  // Points this node acts on: those of the streams of its chain, or every point when the chain
  // above it holds no stream generator. Refreshed by the evaluator before each cook.
  const std::vector<uint32_t>& members;
  bool all_points = true;  // true when members holds every point in order
  int stream = -1;         // for a source: the stream id it emits into
  int threads = 0;
  uint64_t seed = 0;       // graph seed mixed with the node's index
  std::string node_name;
  std::string base_dir;  // folder of the graph file, for relative paths
  // Per collider (same order as `colliders`), for enable_collision_feedback; a node that adds to
  // it also sets *feedback_on so the frame's row is written.
  std::vector<ColliderFeedback>* feedback = nullptr;
  bool* feedback_on = nullptr;
  // The variables `params` were evaluated with (start of the substep), so a node can evaluate a
  // copy of its parameters at another moment (the target node poses at the substep's end).
  const ExprVars* vars = nullptr;
  // Error control (solver `error_control`): a grains node raises this to the substep's error,
  // the mean overlap of its touching grains over their summed radii. Null when off.
  float* substep_error = nullptr;
  size_t max_points = kDefaultMaxPoints;  // the point budget (check_point_budget)
};

// How far a grain may move in one substep before error control refines it (solver
// `error_control`, engine/simulation.cpp motion_substeps), as fractions of its radius: `step`
// bounds |v| dt + |a| dt^2, `fall` bounds a resting grain's fall |a| dt^2. A contact solver whose
// answer needs finer steps than the neighbour search does (grains `contact_solver gauss_seidel`)
// asks for tighter ones; a chain takes the tightest any of its nodes asks for.
struct MotionBounds {
  double step = 0.5;
  double fall = 1.0 / 64;
};

class StateWriter;  // engine/state_stream.h
class StateReader;

class Node {
 public:
  virtual ~Node() = default;
  // Called once per substep, in chain order.
  virtual void cook(CookContext& ctx) = 0;
  // What the node carries from one frame into the next (a source's emission clock, the grains
  // solver's contact history, ...): everything of it that the next frames' results depend on,
  // and nothing they recompute. save_state writes it at the end of a frame; load_state reads it
  // into a node made fresh for the same graph, which then cooks on as the saved one would have,
  // bit for bit (grains run --checkpoint-every / --resume). Nodes that carry nothing keep these.
  virtual void save_state(StateWriter&) const {}
  virtual void load_state(StateReader&) {}
  // Error control's motion measure (engine/motion.h) over every grain (point with ispbd 1), made
  // where this node holds their velocities (ParticleStore::hold): each grain into *worst and
  // *fall as engine/motion_need.h's gr_motion_need adds it, from the grains' velocities, masses,
  // radii and forces as the store holds them. False, with nothing added, where it cannot; the
  // caller then reads the velocities, which brings them back.
  virtual bool held_motion(const ParticleStore&, double /*fps*/, const MotionBounds&,
                           double* /*worst*/, double* /*fall*/) {
    return false;
  }
};

enum class NodeRole {
  Pop,       // acts on particles in a chain
  Source,    // a stream generator: emits particles, nodes below act on its stream only
  Merge,     // combines chains
  Solver,    // ends a chain: one particle object, runs substeps
  Collider,  // a shape referenced by solvers
};

struct NodeTypeInfo {
  std::string type;
  std::string doc;
  NodeRole role = NodeRole::Pop;
  // reports a substep error (CookContext::substep_error): a solver's error control acts only on
  // chains holding such a node
  bool reports_error = false;
  // The motion bounds the node's parameters ask error control for (MotionBounds); unset: the
  // defaults.
  std::function<MotionBounds(const ParamSet&)> motion_bounds;
  std::vector<ParamDecl> params;
  std::function<std::unique_ptr<Node>()> make;
  // Colliders only: the shape and pose for evaluated parameters (base_dir: the graph's folder,
  // for files).
  std::function<void(const ParamSet&, const std::string& base_dir, ColliderState&)> collider;
  // Extra load-time checks on authored parameters (file exists, ...); returns an error message
  // and the offending parameter name, or an empty message.
  std::function<std::pair<std::string, std::string>(const ParamSet&, const std::string& base_dir)>
      check;
  // Point attributes outside the known table (known_point_attributes) that the node adds with
  // these parameters, e.g. a group's group_NAME; "*" when they come from an input file. Loading
  // refuses an /output/attributes name that no node adds.
  std::function<std::vector<std::string>(const ParamSet&)> adds_attributes;

  const ParamDecl* find_param(const std::string& name) const;
};

// The registry of node types (filled by register_builtin_nodes in nodes/).
void register_node_type(NodeTypeInfo info);
const NodeTypeInfo* find_node_type(const std::string& type);
std::vector<const NodeTypeInfo*> node_types();  // sorted by type name

}  // namespace grains
