// Parameter channels: a constant, an expression (muparser) evaluated every substep, or keyframes
// over seconds. Local variables follow DESIGN §2 and the help page's Locals section.
#pragma once
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace grains {

// Thrown when an expression does not parse or cannot be evaluated; what() says why.
struct ExprError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// The local variables an expression can read, with the help page's meaning.
struct ExprVars {
  double ST = 0;        // simulation time (s), 0 at the start
  double SF = 0;        // simulation frame = ST / TIMESTEP
  double T = 0;         // time (s); equals ST (no offset)
  double F = 1;         // Houdini frame, 1-based = SF + 1 (fractional at substeps; $FF too)
  double TIMESTEP = 0;  // one frame's step (s) = 1 / fps
  double SFPS = 0;      // 1 / TIMESTEP
  double OBJ = 0;       // index of the object among those this node processes
  double OBJID = 0;     // unique object id
  double NOBJ = 1;      // number of objects this node processes
  double SNOBJ = 1;     // number of objects in the simulation
  double OBJCT = 0;     // time the object was created (s)
  double OBJCF = 0;     // frame the object was created
  double DATACT = 0;    // time this node's data was created (s)
  double DATACF = 0;    // frame this node's data was created
  std::string OBJNAME;  // object (solver) name
  std::string DOPNET;   // the graph's name
  std::string ALLOBJIDS;    // the ids of every object this node processes, space-separated
  std::string ALLOBJNAMES;  // and their names
  // RELNAME, RELOBJIDS, RELOBJNAMES, RELAFFOBJIDS, RELAFFOBJNAMES: set only when data is attached
  // to a relationship (a Constraint DOP's anchors); no node here attaches any, so they are empty
  // previous value of each of the node's own channels, by channel name (0 before the first)
  const std::map<std::string, double>* channels = nullptr;
};

// A compiled muparser expression. Variables are written `$NAME` or `NAME`; strings compare with
// strcmp($OBJNAME, "sand") (0 when equal; also $DOPNET, $ALLOBJIDS, $ALLOBJNAMES and the REL*
// variables) and are resolved when the object's strings change.
class Expression {
 public:
  // channel_names: the node's channel names, readable as local variables (previous values).
  // Throws ExprError if the text does not parse.
  // bound: further variables, each read from its double at every eval (the attribute node's
  // point variables: ID, PT, TX, @name, ...); names may start with '@'.
  Expression(const std::string& text, const std::vector<std::string>& channel_names,
             const std::vector<std::pair<std::string, double*>>& bound = {});
  ~Expression();
  Expression(Expression&&) noexcept;
  Expression& operator=(Expression&&) noexcept;
  double eval(const ExprVars& vars);
  const std::string& text() const;
  // whether the text reads the variable written `name` (a bound one: "TX", "$TX", "@mass")
  bool uses(const std::string& name) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Keyframes over seconds; held constant outside the first and last key.
struct Keyframes {
  std::vector<std::pair<double, double>> keys;  // (time s, value), strictly increasing time
  bool cubic = false;                           // false: linear; true: Catmull-Rom cubic
  double eval(double t) const;
};

// One scalar channel of a parameter.
class Channel {
 public:
  Channel() = default;
  static Channel constant(double v);
  static Channel expression(const std::string& text, const std::vector<std::string>& channel_names);
  static Channel keyframes(Keyframes k);
  double eval(const ExprVars& vars);  // keyframes read vars.ST
  bool is_constant() const { return kind_ == Kind::Constant; }

 private:
  enum class Kind { Constant, Expr, Keys } kind_ = Kind::Constant;
  double value_ = 0;
  std::shared_ptr<Expression> expr_;
  Keyframes keys_;
};

}  // namespace grains
