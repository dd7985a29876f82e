// Error control's motion measure (solver `error_control`): how many substeps a frame the grains'
// motion needs.
#pragma once
#include "engine/node.h"
#include "engine/particles.h"

namespace grains {

// The fewest substeps of a frame (fps) in which no point moves more than bounds.step of its
// radius in a substep, |v| dt + |a| dt^2 <= step r (a = force / mass, the last substep's): the
// motion the neighbour candidates (1.5 x the summed radii) and the contacts can follow; r / 2
// unless a node asks for less (MotionBounds). Only grains count (ispbd 1 after the last
// substep): the solver sweeps its other points through the whole step. Points without a radius
// are skipped; the answer is capped at `most`.
// A resting grain's fall in one substep, |a| dt^2, is also held to bounds.fall r: the contacts
// project each substep's fall back out, and a fall comparable to the curvature of the grains it
// rests on carries it over their barriers. A grain in the pocket of three fixed grains, gravity
// tilted towards an edge of the pocket, frictionless, leaves it at 12.5, 16.4, 18.0, 18.8 and
// 19.1 degrees with falls of 0.21, 0.053, 0.013, 0.0033 and 0.0008 r (4 to 64 substeps of a
// 24 fps frame, 1 cm grains; rigid spheres leave at 19.5, LIGGGHTS' Hertz grains at 18.6).
// r / 64, the default, is 16 substeps for 1 cm grains at 24 fps (tests/nodes/grains/
// test_pockets.cpp; docs/heap-angle.md "Pockets and pyramids").
// `holder`: the node that holds the velocities (ParticleStore::hold), which makes the measure
// where it holds them when it can (Node::held_motion); else they are read here, which brings
// them back. Each grain's part is engine/motion_need.h's.
int motion_substeps(const ParticleStore& pts, double fps, int most, const MotionBounds& bounds,
                    Node* holder = nullptr);

// The measure's maxima over the store's grains read here, each grain added into *worst and
// *fall (gr_motion_need); false, with nothing added, without velocities, radii or ispbd.
bool motion_need(const ParticleStore& pts, double fps, const MotionBounds& bounds, double* worst,
                 double* fall);

}  // namespace grains
