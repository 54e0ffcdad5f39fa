"""Plan shapes for OGBench pointmaze: how many states a plan has and how many environment steps apart.

The one place that says it for the pointmaze family (:func:`bridgeplan.config.plan_shape` asks here for any
``pointmaze-...`` name, as it asks Diffuser's table for Maze2D). Open loop, one plan made at an episode's first
step has to reach the goal, so its span, ``(horizon - 1) * stride + 1`` steps, must cover the longest of the
maze's 5 evaluation tasks at the pace of the data the planner imitates:

- the noise-free oracle on the protocol (50 episodes per task, seed 0; ``bridgeplan oracle``)
  needs at most, over its successful episodes (90th percentile; the maximum is the same but for a few episodes
  that hung on a wall corner first): medium 169 steps (tasks 1-5: 169, 165, 95, 161, 135), large 325 (266,
  325, 225, 246, 266), giant 511 (511, 455, 488, 440, 287), teleport 601 (601, 269, 60, 72, 346; its BFS
  ignores the teleporters, so these are not shortest paths);
- the datasets' expert is that oracle with N(0, 0.5^2) action noise, clipped to [-1, 1]: its progress along
  the oracle's direction is 0.80-0.88 of the oracle's per step, so it covers a task in ~1.25x the oracle's steps
  (medium ~210, large ~410, giant ~640).

``cpu-small`` plans every 8th step (Maze2D's cpu-small medium shape, which trains on this 2-core CPU in minutes):
medium 32 states (249 steps, that shape itself: ~20% over the ~210 needed), large 56 (441) and giant 84 (665),
the smallest multiples of 4 (the U-Net's downsampling) whose span covers the longest task at the data's pace;
teleport has large's map size and takes large's shape (its oracle times are not shortest paths to plan for).
``diffuser`` plans every step over
the same span, rounded up to a multiple of 8. Stitch datasets hold 201-step episodes, shorter than every
evaluation task, so no window of theirs spans one: their plans are 24 states (185 steps) whatever the maze, and
reaching a far goal from them needs replanning (a goal farther than any window ever went is outside what the
planner learned; the stitch datasets are built to test exactly that).
"""

from __future__ import annotations

from bridgeplan.envs.ogbench_pointmaze.names import EVAL_EPISODE_STEPS, parse_dataset_name
from bridgeplan.trajectory import span

STRIDE = 8
"""cpu-small's environment steps between planned states."""
NAVIGATE_HORIZON = {"medium": 32, "large": 56, "giant": 84, "teleport": 56}
"""cpu-small's planned states per navigate plan, per maze (see the module docstring)."""
STITCH_HORIZON = 24
"""cpu-small's planned states per stitch plan: (24 - 1) * 8 + 1 = 185 steps fit the 201-step episodes."""
DIFFUSION_STEPS = 256
"""The ``diffuser`` preset's diffusion steps (Diffuser's medium and large Maze2D value)."""


def plan_shape(name: str, preset: str) -> tuple[int, int]:
    """``(horizon, stride)`` of ``preset``'s plans for dataset ``name`` (``pointmaze-medium-navigate-v0``)."""
    spec = parse_dataset_name(name)
    horizon = STITCH_HORIZON if spec.kind == "stitch" else NAVIGATE_HORIZON[spec.maze]
    if preset == "cpu-small":
        return horizon, STRIDE
    return 8 * -(-span(horizon, STRIDE) // 8), 1  # diffuser


def episode_steps(name: str) -> int:
    """The longest plan span for dataset ``name``: an evaluation episode's steps, or the dataset's episode if
    shorter (a training window lies inside one episode)."""
    return min(EVAL_EPISODE_STEPS, parse_dataset_name(name).episode_steps)
