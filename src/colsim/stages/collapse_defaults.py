"""The collapse stage's defaults, plain constants: the stage's settings, the CLI's help and the
summary's flags read them here, before (or without) loading the engine."""

#: end time t/sqrt(h0/g) and steps to it: dt/sqrt(h0/g) = 0.004, where the results stop depending on
#: the step (docs/validation/time-step.md); the paper's is 100 steps
DURATION = 4.0
STEPS = 1000
#: a frame every this many steps; a checkpoint every this many (and after 10 minutes without one)
FRAME_EVERY = 25
CHECKPOINT_EVERY = 100
#: at rest: h_inf and r_inf steady over REST_WINDOW (t/sqrt(h0/g)) to within REST_TOLERANCE mean
#: diameters, and the kinetic energy below REST_ENERGY of its peak
REST_WINDOW = 1.0
REST_TOLERANCE = 0.1
REST_ENERGY = 1e-2
