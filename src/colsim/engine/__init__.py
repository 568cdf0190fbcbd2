"""The engine: spheres and walls (state), contact detection, one step's second-order cone program
(program, its cones and the contract a solver meets), the warm start, the Coulomb law's fixed point
(friction) and the time loop (stepper). It imports nothing else of colsim."""
