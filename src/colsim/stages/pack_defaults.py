"""The packing stage's defaults, plain constants: the CLI shows them in its help before it loads the
engine."""

#: the most spheres a packing may hold unless told otherwise: 3x the r0 = 8, a = 5 column's 160,000,
#: about 4 GB of packing; r0 = 20 would pour 2.4 million and run out of memory on a 24 GB machine
DEFAULT_MAX_SPHERES = 500_000

#: Filling in layers (:func:`pack`): the settled thickness each cloud adds (length, the paper's
#: diameters 0.25-0.5; measured at 2.5), None for one cloud: the default, since the layers' deposits
#: at a = 5 are not yet the pour's (docs/validation/packing-layers.md); and the depth below the
#: settled surface from which slow spheres are fixed.
LAYER_HEIGHT = None
FREEZE_DEPTH = 3.5
#: a packing writes its checkpoint every this many steps (an r0 = 4 pour's steps take 3-4 s of CPU,
#: so at most about 100 s of work is lost to a killed job), and after 10 minutes without one
#: (colsim.stages.stopwatch.CHECKPOINT_INTERVAL_S: an r0 = 6 pour's steps take up to a minute)
CHECKPOINT_EVERY = 25

#: the pour's step over sqrt(d_min / g), the time to fall about a diameter, must lie in this range:
#: the default (dt 0.02, d_min 0.25, g 9.81) is 0.125; far above, spheres cross each other within a
#: step, far below, the pour takes millions of steps (gravity 1e-300 had the spheres fly off while a
#: study reported a deposit)
POUR_STEP_RANGE = (1e-4, 2.0)
