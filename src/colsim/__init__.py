"""colsim: granular column collapse by non-smooth contact dynamics.

Each time step is one second-order cone program (contact forces with Coulomb friction and a
rolling-resistance cone), solved by Clarabel (the reference) or, at the collapse's small steps, by
warm-started APGD on the same program (:mod:`colsim.solvers`); see :mod:`colsim.engine.program` for
the formulation and docs/ for the pipeline.
"""
__version__ = "0.1.0"
