"""colsim: granular column collapse by non-smooth contact dynamics.

Each time step is one second-order cone program (contact forces with Coulomb friction and a
rolling-resistance cone), solved by Clarabel; see :mod:`colsim.engine.program` for the formulation.
"""
__version__ = "0.1.0"
