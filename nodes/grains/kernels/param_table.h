/* The grains node's parameters, each declared once (an X-macro list, after MuJoCo's
 * mjxmacro.h). Every expansion reads this table:
 *   - the declarations the loader validates against, `grains nodes`, docs/nodes.md and the graph
 *     schema print (grains_node.cpp: GR_PARAM_DECL);
 *   - GrainsSettings, the node's evaluated parameters, one member per row with the row's default
 *     (solver.h), and the evaluation that fills it (grains_node.cpp);
 *   - gr_params, the kernels' parameter struct: one field per KERNEL row, copied from
 *     GrainsSettings each substep (params.h, solver.cpp make_params).
 * A parameter the kernels read is one row here (home KERNEL) and its use in a kernel.
 *
 * GR_PARAM(kind, name, default, home, modifiers, meaning)
 *   kind      FLOAT, INT, TOGGLE, VECTOR, MENU or STRING (ParamDecl's types)
 *   name      the help page's label in snake_case: the graph's key, the C++ member and the kernel
 *             field alike
 *   default   a number; VECTOR: (x, y, z); MENU: the default choice's index; STRING: a literal
 *   home      KERNEL: also a field of gr_params; HOST: read by the node and the solver's host code
 *   modifiers ParamDecl modifiers (.at_least(0), .range(0, 2), .scaled_by("friction"),
 *             .unit("m"), .menu_of({...})), or nothing
 *   meaning   one line for `grains nodes`
 * Rows keep the help page's order. Plain C: the kernels include it. */
GR_PARAM(FLOAT, activation, 1, HOST, ,
         "the node acts only while this is greater than 0")
GR_PARAM(STRING, group, "", HOST, ,
         "act only on this point group of the stream (empty: the whole stream)")
GR_PARAM(FLOAT, particle_separation, 0.1, HOST, .positive().unit("m"),
         "mean grain diameter hint: radius of points without pscale, mass-shock length scale")
GR_PARAM(INT, constraint_iterations, 10, HOST, .range(1, 100000),
         "Jacobi iterations per substep; about twice the stacking height")
GR_PARAM(TOGGLE, assume_uniform_radius, 1, HOST, ,
         "search every grain as the largest one, with one grid cell size: faster; for grains of one size")
/* friction (Macklin 2014 eqs. 23-25; kernels/iterate.h gr_friction_pass): Coulomb's law bounded
 * by the normal correction each contact applied in the substep */
GR_PARAM(FLOAT, friction_with_colliders, 1, KERNEL, .at_least(0).scaled_by("friction"),
         "grain-collider Coulomb friction: a lab mu is this with static_threshold 1 and scale_kinetic 1")
GR_PARAM(FLOAT, friction_with_particles, 1, KERNEL, .at_least(0).scaled_by("friction"),
         "grain-grain Coulomb friction: static mu = this x static_threshold, kinetic mu = this x scale_kinetic")
GR_PARAM(TOGGLE, accurate_friction, 1, HOST, ,
         "apply friction after every iteration instead of once after the loop (contact_solver jacobi only)")
GR_PARAM(FLOAT, static_threshold, 1, KERNEL, .at_least(0),
         "static friction: slip under this x friction x the contact's normal correction in the substep is removed")
GR_PARAM(FLOAT, scale_kinetic, 0.5, KERNEL, .at_least(0),
         "kinetic friction: beyond it, a substep removes at most this x friction x the normal correction")
GR_PARAM(FLOAT, contact_memory, 0.01, KERNEL, .at_least(0).scaled_by("friction"),
         "slip a stuck contact remembers and pulls back in later substeps, at most this x the static "
         "coefficient x the summed radii (a DEM contact's tangential spring), and no more than one substep of its "
         "static friction pulls back; 0: none, a heap creeps (not in POP Grains; contact_solver jacobi only)")
/* internal collisions (kernels/contact.h); weight 0 = off */
GR_PARAM(FLOAT, internal_collisions_weight, 1, KERNEL, .range(0, 2).scaled_by("repulsionweight"),
         "weight of grain-grain collisions; 0 disables them")
GR_PARAM(FLOAT, internal_collisions_stiffness, 1000, KERNEL, .at_least(0).scaled_by("repulsionstiffness"),
         "stiffness of grain-grain collisions; full at substeps x iterations")
/* mass-shock scaling (kernels/mass_shock.h) */
GR_PARAM(TOGGLE, enable_mass_shock_scaling, 0, HOST, ,
         "make higher grains lighter so stacks converge faster")
GR_PARAM(MENU, mass_shock_method, 0, HOST, .menu_of({"global", "local"}),
         "global: write shockmass before iterating; local: pair mass ratio on the fly (power clamped near 7)")
GR_PARAM(FLOAT, shock_scaling_power, 1, HOST, .at_least(0),
         "0: no ratio; 1: a 15% ratio between two stacked grains")
GR_PARAM(VECTOR, shock_axis, (0, 1, 0), HOST, ,
         "up vector of the mass gradient (against gravity)")
GR_PARAM(VECTOR, shock_origin, (0, 0, 0), HOST, .unit("m"),
         "rough centre of the grains; far grains clamp to min/max mass")
/* clumping (kernels/clumping.h); weight 0 = off */
GR_PARAM(FLOAT, clumping_weight, 0, KERNEL, .range(0, 2).scaled_by("attractionweight"),
         "weight of the pull between nearby grains; 0 disables clumping")
GR_PARAM(FLOAT, clumping_stiffness, 100, KERNEL, .at_least(0).scaled_by("attractionstiffness"),
         "stiffness of clumping")
/* explicit constraints (kernels/distance.h): 2-point primitives keep their restlength */
GR_PARAM(FLOAT, explicit_constraints_weight, 1, KERNEL, .range(0, 2).scaled_by("constraintweight"),
         "weight of the distance constraints of 2-point primitives (restlength); 0 skips them entirely")
GR_PARAM(FLOAT, explicit_constraints_stiffness, 1000, KERNEL, .at_least(0).scaled_by("constraintstiffness"),
         "stiffness of explicit constraints; full at substeps x iterations")
GR_PARAM(TOGGLE, collide_mutually_constrained_particles, 0, KERNEL, ,
         "let constrained pairs collide too (needs them apart at rest)")
/* strain e = (|x_i - x_j| - L) / L at the end of the substep (solver.cpp update_constraints).
 * Instantaneous: strain = e. Accumulating: strain <- strain x exp(-strain_decay dt) + (e_end -
 * e_start), the change of stretch over the substep added to a memory that fades at strain_decay:
 * with decay 0 it follows e, with decay > 0 only recent stretching counts, so slow deformation is
 * forgiven (plastic-like) while a fast pull still breaks. */
GR_PARAM(TOGGLE, instantaneous_strain, 1, HOST, ,
         "strain = (length - restlength) / restlength at the end of each substep; off: it accumulates "
         "each substep's change and fades at strain_decay")
GR_PARAM(FLOAT, strain_decay, 1, HOST, .at_least(0).unit("1/s"),
         "rate at which accumulated strain fades (instantaneous_strain off)")
GR_PARAM(TOGGLE, break_constraints, 0, HOST, ,
         "remove a constraint once |strain| exceeds strength x break_threshold")
GR_PARAM(FLOAT, break_threshold, 0.05, HOST, .positive(),
         "strain that breaks a constraint of strength 1 (0.05: 5% stretch)")
GR_PARAM(TOGGLE, remove_strands, 0, HOST, ,
         "remove chain-only constraints (both endpoints with at most 2 constraints), until none is left")
/* solver controls */
GR_PARAM(INT, max_neighbors, 32, HOST, .at_least(1),
         "most neighbour candidates kept per grain (nearest first)")
GR_PARAM(FLOAT, neighbor_query_scale, 1.5, KERNEL, .at_least(1),
         "candidates closer than this times the summed radii; also the clumping range")
GR_PARAM(FLOAT, max_speed, 1e6, KERNEL, .positive().unit("m/s"),
         "cap on the reported speed (positions are not limited)")
GR_PARAM(FLOAT, max_acceleration, 1e6, KERNEL, .positive().unit("m/s^2"),
         "cap on the velocity change constraints cause")
GR_PARAM(FLOAT, drift_threshold, 0, KERNEL, .at_least(0).unit("m/s"),
         "grains slower than this stay where they were")
GR_PARAM(FLOAT, velocity_blend, 0, KERNEL, .range(0, 1),
         "blend of the new velocity with the predicted one")
GR_PARAM(FLOAT, sleep_speed, 0.5, HOST, .at_least(0).unit("radii/s"),
         "sleeping (not in POP Grains; 0 = off), in grain radii per second: a grain that stays within "
         "sleep_speed x sleep_time radii of one place for sleep_time holds still, as a fixed grain, until "
         "a grain faster than 4 x sleep_speed (beyond one substep's fall) touches it, a collider that "
         "moved touches it, a grain it touched leaves or is removed, it is moved from outside, or its "
         "force changes by 1%; pinned and constrained grains never sleep, nor any with add_impact_data or "
         "enable_collision_feedback on (a sleeper exchanges no impulse with the colliders)")
GR_PARAM(FLOAT, sleep_time, 0.5, HOST, .positive().unit("s"),
         "how long a grain must stay within sleep_speed x sleep_time radii of one place to fall asleep")
GR_PARAM(FLOAT, over_relaxation, 1, KERNEL, .range(0, 2),
         "scale of the averaged corrections (jacobi), of each contact's normal step (gauss_seidel) and of "
         "the constraints' corrections; above 1 converges faster")
GR_PARAM(FLOAT, chebyshev_rho, 0, HOST, .range(0, 0.95),
         "Chebyshev acceleration of the iterations after the first 5 (not in POP Grains): the estimated "
         "spectral radius of the Jacobi iteration, 0 = off; piles take 0.9-0.95, higher diverged (contact_solver "
         "jacobi only)")
GR_PARAM(MENU, contact_solver, 1, HOST, .menu_of({"jacobi", "gauss_seidel"}),
         "gauss_seidel (the default; not in POP Grains): contacts and collider planes one at a "
         "time, each with its own Coulomb cone, their loads carried to the next substep, over_relaxation "
         "scaling each normal step; error control keeps a grain's motion a substep under r / 4 and a "
         "resting fall under r / 256. jacobi: every grain averages its contacts' corrections, as POP "
         "Grains; accurate_friction, contact_memory, chebyshev_rho and the updates during iterations work "
         "with it only (set with gauss_seidel they are refused)")
GR_PARAM(TOGGLE, pre_stabilization, 1, HOST, ,
         "remove the overlap grains start a substep with, without turning it into velocity (Macklin et al. 2014 sec. 4.4)")
GR_PARAM(TOGGLE, update_collisions_during_iterations, 0, HOST, ,
         "re-find collider planes every iteration (contact_solver jacobi only)")
GR_PARAM(TOGGLE, update_neighbors_during_iterations, 0, HOST, ,
         "re-find neighbours every iteration (contact_solver jacobi only)")
GR_PARAM(TOGGLE, final_collision_test, 1, HOST, ,
         "a swept collision pass after the loop: no leaks through thin or moving colliders")
GR_PARAM(TOGGLE, disable_constraint_averaging, 0, KERNEL, ,
         "sum corrections instead of averaging them (momentum-preserving)")
/* pins (kernels/pin.h); weight 0 or no targetstiffness attribute = off */
GR_PARAM(FLOAT, target_weight, 1, KERNEL, .range(0, 2).scaled_by("targetweight"),
         "weight of the pull toward targetP; 0 disables pins")
GR_PARAM(FLOAT, target_stiffness, 1000, KERNEL, .at_least(0).scaled_by("targetstiffness"),
         "stiffness of pins; full at substeps x iterations; no targetstiffness attribute = no pin")
GR_PARAM(TOGGLE, enable_rigid_shape_matching, 0, HOST, ,
         "keep each connected component (grains joined by 2-point primitives) a best-fit rigid placement of its rest shape")
GR_PARAM(TOGGLE, add_impact_data, 0, HOST, ,
         "write impact, impactP, impactN, impactimpulse (N s), impactother (collider index) for collider contacts")
GR_PARAM(TOGGLE, enable_collision_feedback, 0, HOST, ,
         "accumulate the force and torque the grains put on each collider (DIR/colliders.csv)")
/* the OpenCL backend (opencl/iterations.h) */
GR_PARAM(TOGGLE, use_opencl, 0, HOST, ,
         "run the iterations (either contact_solver's passes), friction passes and pins on an OpenCL device: "
         "GRAINS_OPENCL_DEVICE=P:D picks it (`grains devices` lists them)")
