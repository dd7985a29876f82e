// The evaluator (DESIGN §3): runs each solver's POP chain top-down every substep.
//
// For each frame, each solver (one particle object) runs `substeps` substeps of
// dt = 1 / (fps * substeps). In a substep: `force` is cleared and `ispbd` reset to 0; the
// colliders the solver names are posed at the end of the substep (their pose at its start is
// kept, which gives their surface velocity); the chain runs in order — a node's inputs before
// it, left to right — each node acting on the points of its chain's streams; then the solver
// moves the points whose `ispbd` is still 0.
#pragma once
#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include "engine/graph.h"
#include "engine/node.h"
#include "engine/param_rows.h"
#include "engine/state_stream.h"

namespace grains {

struct FrameStats {
  int frame = 0;
  double time = 0;
  size_t points = 0;
  size_t constraints = 0;
  double wall_ms = 0;
  float max_penetration = 0;   // max over overlapping pairs of overlap / (r_i + r_j)
  float mean_penetration = 0;  // mean over overlapping pairs
  float max_strain = 0;        // max |strain| over constraints
  double kinetic_energy = 0;   // sum of m v^2 / 2 (J)
  int substeps = 0;            // substeps the frame took (error control may vary it)
  float error = 0;             // largest substep error the grains nodes reported (0: none)
  // collision feedback (enable_collision_feedback): the frame's mean force (N) and torque (N m,
  // about the collider's translate) on each collider; empty when no node reported any
  struct ColliderForce {
    std::string name;
    Vec3 force, torque;
  };
  std::vector<ColliderForce> colliders;
  // float precision where the points are: the largest |coordinate| (m), the spacing of floats
  // there (m), and the smallest positive pscale (m; 0 when none)
  float max_coordinate = 0, resolution = 0, min_radius = 0;
};

// A frame's figures in one line (what --verbose prints each frame): "27 points, 0 constraints,
// 2 substeps, error 0, kinetic energy 0.0123 J, max_penetration 0.0000, 1.2 ms".
std::string frame_detail(const FrameStats& s);

// Positions are floats: at distance x from the origin they are resolved to the float spacing
// there, 2^(floor(log2 x) - 23) (1 m at 1e7 m). A frame whose resolution reaches
// kCoarsestResolution of the smallest grain radius stops the run (grains there cannot be told
// apart: a pile collapses onto a few positions); past kWarnResolution `run` warns, since contacts
// are then solved no finer than that.
constexpr float kCoarsestResolution = 0.1f;
constexpr float kWarnResolution = 1e-3f;
// The largest distance from the origin at which floats resolve `fraction` of radius r.
double precise_reach(float r, float fraction);

// The solver node's parameters (engine/param_rows.h): nodes/solver.cpp registers them with the
// node, and the evaluator, which runs each solver's substeps, reads them.
#define SOLVER_PARAMS(ROW)                                                                       \
  ROW(INT, substeps, 1, .range(1, 1000000),                                                     \
      "substeps per frame, dt = 1 / (fps * substeps); with error control the fewest")           \
  ROW(TOGGLE, error_control, true, ,                                                            \
      "pick the substeps each frame to keep the grains' error under error_tolerance")           \
  ROW(INT, max_substeps, 256, .range(1, 1000000),                                              \
      "most substeps per frame error control may take")                                         \
  ROW(FLOAT, error_tolerance, 0.0025, .positive(),                                              \
      "error control's bound on the mean overlap of touching grains, as a fraction "            \
      "of their summed radii (a resting column's relative loss of height)")                     \
  ROW(LIST, colliders, {}, , "names of collider nodes this object collides with")
GR_NODE_PARAMS(SolverParams, SOLVER_PARAMS)

// One chain entry: a node instance with its parameters, evaluated per substep.
struct ChainNode {
  int node = -1;                // index into Graph::nodes
  std::vector<int> streams;     // stream ids this node acts on; empty = every point
  std::unique_ptr<Node> impl;
  ParamSet params;
};

struct SimObject {
  std::string name;  // the solver node's name (OBJNAME)
  int objid = 0;
  int solver = -1;   // index of the solver node
  ParticleStore pts;
  std::vector<ChainNode> chain;  // cook order, solver last
  std::vector<int> collider_nodes;
  std::vector<ParamSet> collider_params;
  std::vector<ColliderState> colliders;
  bool colliders_posed = false;
  std::vector<ColliderFeedback> feedback;  // per collider, this frame (see ColliderFeedback)
  bool feedback_on = false;
  int substeps = 0;  // error control: the count the next frame starts with (0: the solver's own)
  FrameStats stats;
};

// The most worker threads a command accepts (--threads): far past any machine's cores, short of
// where the OpenMP runtime fails to start them.
constexpr int kMaxThreads = 1024;

class Simulation {
 public:
  // threads <= 0: OpenMP's default.
  Simulation(const Graph& graph, int threads = 0);
  // the point budget the nodes emit under (CookContext::max_points)
  void set_max_points(size_t n) { max_points_ = n; }
  ~Simulation();

  // Replaces an object's points before the first frame (cook_node's starting state).
  void set_points(size_t object, ParticleStore pts) { objects_[object]->pts = std::move(pts); }
  // Advances every object by one frame.
  void step_frame();
  int frame() const { return frame_; }  // frames completed
  // The run's state at the end of frame(): each object's points, collider poses and substep
  // count, and what each of its nodes carries (Node::save_state). load_state reads it into a
  // Simulation made from the same graph, before its first step_frame; the frames after it are
  // then those the saved run would have made, bit for bit. A state of another graph (other
  // solvers or chains) is refused (StateError).
  void save_state(StateWriter& w) const;
  void load_state(StateReader& r);
  const Graph& graph() const { return graph_; }
  size_t object_count() const { return objects_.size(); }
  SimObject& object(size_t k) { return *objects_[k]; }
  const SimObject& object(size_t k) const { return *objects_[k]; }

 private:
  void step_object(SimObject& obj);
  ExprVars vars_for(const SimObject& obj, int node, double st) const;
  void pose_colliders(SimObject& obj, double t_end, double dt);
  // Runs f, which evaluates or cooks `node`; a parameter value out of its declared range
  // (ParamRangeError, from an expression or keys) becomes the loader's error for that parameter
  // at this frame: the graph file, the parameter's JSON pointer, the frame, the value.
  template <class F>
  void checked(int node, F&& f);

  Graph graph_;
  int threads_ = 0;
  size_t max_points_ = kDefaultMaxPoints;
  int frame_ = 0;
  std::vector<std::unique_ptr<SimObject>> objects_;
  // The objects each node processes, in solver order ($OBJ, $NOBJ), and their ids and names as
  // the space-separated strings $ALLOBJIDS and $ALLOBJNAMES; fixed once the objects are built.
  struct NodeObjects {
    std::vector<const SimObject*> objects;
    std::string ids, names;
    void add(const SimObject* o) {  // once, however many ways the object uses the node
      if (objects.empty() || objects.back() != o) objects.push_back(o);
    }
  };
  std::vector<NodeObjects> node_objects_;
};

// Computes the per-frame diagnostics of an object's points (penetration, energy, strain).
void measure_frame(const ParticleStore& pts, FrameStats& stats);

}  // namespace grains
