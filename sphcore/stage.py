"""A stage of a step's plan (sphcore.plan): which shader runs, at which level, and when."""
from collections import namedtuple

Stage = namedtuple("Stage", "name level indirect when")  # level: the HistoPyramid level a reduce_cells builds,
#   the solve of a DFSPH stage (dfsph.glsl: 1 divergence-free, 2 constant density), compute_density's walk of
#   reused lists (1), on a rank whose exchange overlaps the step's end (sphcore.parallel) compute_forces' rows
#   (1 the pick's, 2 the others) and pick_rows' before integrate (1), on a rank choose_dt's largest partial (1),
#   else 0; indirect: its work groups are read from a buffer when it runs (backends.indirect_source: a DFSPH
#   solve's from control, a rank's from rank_groups), as vkCmdDispatchIndirect does; when: with reused lists
#   (spec.LIST_SKIN), BUILD for a stage that runs only at a build of the lists, REUSE only between builds, as
#   control[CONTROL_REBUILD] says when it runs (on Vulkan by conditional rendering), else ALWAYS
ALWAYS, BUILD, REUSE = 0, 1, 2
Stage.__new__.__defaults__ = (0, False, ALWAYS)
