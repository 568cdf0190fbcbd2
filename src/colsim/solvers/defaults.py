"""Every solver default, in one place: the back-ends, the CLI's help, the config schema and the docs
(docs/solvers.md, "Defaults") read them from here. Plain constants: importing this module loads no
back-end, so the CLI can parse its arguments first.

Where each figure comes from is docs/solvers.md; the measurements are summarised beside each.
"""

#: the back-ends' names, as make_solver, the CLI and the config schema accept them
SOLVERS = ("clarabel", "clarabel-force", "apgd", "admm", "auto")
#: the back-end of pack and collapse unless told otherwise
DEFAULT_SOLVER = "auto"

#: Clarabel's tolerance (its gap and feasibility tolerances) and iteration cap: the reference
CLARABEL_TOLERANCE = 1e-8
CLARABEL_MAX_ITER = 200
#: APGD's relative tolerance and iteration cap when named on its own (`--solver apgd`)
APGD_TOLERANCE = 1e-5
APGD_MAX_ITER = 20_000
#: APGD's Lipschitz estimate shrinks by this factor after each accepted step (and doubles on a failed
#: descent test): about 10 % fewer trial steps a step than 0.9 at r0 = 3 and 6, whose backtracks each
#: cost a trial step (docs/solvers.md, "The Lipschitz estimate's decay")
APGD_LIPSCHITZ_DECAY = 0.97
#: ADMM's relative tolerance and iteration cap
ADMM_TOLERANCE = 1e-3
ADMM_MAX_ITER = 5000

#: auto hands a step to APGD (warm-started, or cold from zero forces) up to this dt / sqrt(h0/g), the largest
#: step measured; Clarabel above (docs/solvers.md, "the auto rule")
AUTO_APGD_BELOW = 0.04
#: auto's APGD iteration cap; a step that reaches it is solved again by Clarabel (docs/solvers.md,
#: "the auto rule": no measured step came within a third of it)
AUTO_MAX_ITER = 20_000
#: APGD's tolerance under auto, from the tolerance study (docs/solvers.md, "APGD's tolerance")
AUTO_APGD_TOLERANCE = 1e-5
#: APGD's length floor under auto, mean diameters: with the tolerance, each contact's end-of-step
#: gap to 1e-6 of a mean diameter at least
AUTO_APGD_LENGTH_FLOOR = 0.1
#: APGD's overlap tolerance under auto in a collapse, mean diameters (docs/solvers.md, "The overlap
#: tolerance"): a step's largest cone violation may reach it while complementarity keeps the
#: relative tolerance
AUTO_APGD_OVERLAP_TOLERANCE = 1e-4

#: the dt / sqrt(h0/g) at which auto's APGD length floor and overlap tolerance hold as given (the
#: default collapse step); at a smaller step both shrink in proportion to it, so the velocity error
#: they admit (a length over dt) does not grow as the step shrinks (docs/method.md, "Overlaps a
#: step starts with")
AUTO_APGD_LENGTHS_AT = 0.004

#: APGD's tolerance when `colsim pack` runs under auto: a settled packing is an initial condition,
#: where 1e-3 of the step's free fall (g dt^2) is 1e-5 of a diameter (docs/solvers.md, "Packing under
#: auto", compares it with Clarabel)
PACK_APGD_TOLERANCE = 1e-3
#: APGD's overlap tolerance under auto in a packing: none (its tolerance is already as loose)
PACK_APGD_OVERLAP_TOLERANCE = 0.0

#: device auto takes a visible GPU for a pour or a column of at least this many spheres. Whole steps
#: are faster on a GPU from a few thousand spheres on (docs/performance.md), but a node's GPU runs its
#: jobs one at a time while its cores run many, so a study's small columns are left to the cores
GPU_FROM_SPHERES = 73_000

#: how APGD's iteration stores its arrays on a GPU: float64, the reference, or float32 (the iterate,
#: T x, the wrenches and the contacts' frames as a trial step reads them; the arithmetic, the stopping
#: test and the step's forces and increments stay float64): about a third fewer bytes an iteration,
#: its float64 checks counted, whose time on a GPU its bytes set (docs/solvers.md, "Float32 storage on
#: a GPU")
GPU_STORAGES = ("float64", "float32")
DEFAULT_GPU_STORAGE = "float64"
#: the back-end a step records (step_solver_backend) when float32 storage reached the cap and APGD then
#: solved the step in float64
FLOAT64_FALLBACK = "apgd-float64-fallback"
