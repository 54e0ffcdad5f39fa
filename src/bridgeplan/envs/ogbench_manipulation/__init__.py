"""OGBench's manipulation suite (Park et al., ICLR 2025) on the ``ogbench`` package, the family :data:`FAMILY`: a
UR5e arm with a gripper, acting in 5 dimensions (effector x, y, z, yaw, gripper; each in [-1, 1]) on cubes
(``cube-single``, ``cube-double``), a scene of a cube, buttons, a drawer and a window (``scene``) and button puzzles
(``puzzle-3x3``, ``puzzle-4x4``).

Its parts: dataset names and observation columns (``names``), a dataset generator in OGBench's play recipe and npz
format, cached by identity (``generate``), reading and checking dataset files (``reading``) and the 5-task
evaluation protocol in ogbench's own environments (``protocol``). Its environment names are the datasets'
(``cube-single-play-v0``).
"""

from __future__ import annotations

from bridgeplan.envs.family import SceneParts
from bridgeplan.envs.ogbench_data import OGBenchFamily, compact_stream
from bridgeplan.envs.ogbench_manipulation.names import (
    ACT_DIM,
    BUTTON_COLUMNS,
    CUBE_COLUMNS,
    CUBE_TOLERANCE,
    EFFECTOR_CENTRE,
    EFFECTOR_SCALE,
    EFFECTOR_XY,
    ROBOT_COLUMNS,
    names,
    parse_dataset_name,
)
from bridgeplan.errors import BridgeplanError
from bridgeplan.trajectory import Layout

SUFFIX = "-play-v0"
GRAPH_GOAL_WEIGHT = 30.0
"""How much more a distance counts in the objects' columns than in the effector's, both standardized
(:meth:`OGBenchManipulation.graph_space`): a jump of the graph's radius 1 moves the effector by up to one standard
deviation (about 6 of the data's steps) and a cube by up to 1/30 of one (2 mm in x, 6 mm in y on cube-single), so the
graph's paths carry cubes by the data's own steps, not by chains of jumps. Chosen on cube-single's validation tasks
(6-10, 10 episodes each; the graph's paths executed by the inverse dynamics): weight 1 (plain standardization) 0 %
(its paths teleport the cube: 26 steps long), 10 42 %, 20 74 %, 30 76 %, 100 2 % (too few jumps: paths of 957 steps)."""
GRAPH = {"keep": 5, "radius": 1.0, "neighbours": 8, "reach": 2.0}
"""The dataset graph's settings, distances in the graph's space: on cube-single's real dataset (1000 x 1001 steps)
every 5th state, 201 k nodes, about 0.3 M jumps, built in 2-8 s on this machine; chosen on its validation tasks
(weight 30; 10 episodes each): keep 5 82 %, keep 10 76 %, keep 20 58 %, radius 0.5 28 % (too few jumps), 1.5 72 %."""
BUTTON_UP = -0.1
"""A button is up (not pushed) while its position column is above this (the joint's position times 120: 0 at a reset,
0.055 at rest, a press toggles at -2.4): pushed by less than 1 mm (``graph --objects`` on a puzzle)."""
GRAPH_RADIUS = {"scene": 12.0}
"""A scene's own radius where :data:`GRAPH`'s joins too few of its states, chosen on its validation tasks (6-10, 10
episodes each, keep 5; studies/manip-scene.toml): scene radius 1-2 0 %, 3 8 %, 4 14 %, 6 16 %, 8 20 %, 12-24 26 % (the
cube's position with the drawer's, the window's and the buttons' is rarely where another episode had them all). On
cube-double no radius helped (1-3 0 %, 6 and 12 2 %): it keeps the family's."""


SLIDE_SCALES = (18.0, 15.0)
"""The drawer's and the window's positions in the observation: the joint's (m) times these (``compute_observation``)."""
SLIDE_TOLERANCE = 0.04
"""How near its goal a slide is done (m of its joint): ``info["success"]``'s."""
DRAWER_OPEN = -0.16
"""The drawer's joint fully open (m; closed at 0): where the cube goes in and out (``drawer.xml``'s range)."""
IN_DRAWER = ((0.21, 0.45), (-0.51, -0.31), (0.0, 0.15))
"""Where a cube lies in the closed drawer (world x, y, z in m): ``SceneEnv._is_in_drawer``'s box about the drawer's
handle, which is at y = -0.24 less the joint's position (the drawer slides along -y as its joint goes negative)."""


class OGBenchManipulation(OGBenchFamily):
    data_package = "bridgeplan.envs.ogbench_manipulation"
    name = "ogbench-manipulation"
    title = "OGBench manipulation"
    generator = "ogbench-manipulation"
    episodes = 50  # per task, as every manipulation line of OGBench's hyperparameters.sh (--eval_episodes=50)
    quick_episodes = 4
    default_arrival = "end"
    path_controller = "track"  # pursuit steers a point in the plane, not an arm (controllers.py)
    picture = "frames"

    @property
    def validation_tasks(self) -> tuple[int, ...]:
        from bridgeplan.envs.ogbench_manipulation.protocol import VALIDATION_TASK_IDS

        return VALIDATION_TASK_IDS

    def owns(self, env: str) -> bool:
        return env.endswith(SUFFIX) and not env.startswith("pointmaze-")

    def names(self) -> str:
        return names()

    def check(self, env: str) -> str:
        return parse_dataset_name(env).name

    def layout(self, env: str) -> Layout:
        """The observation whole as the state; the effector's xy as its position; the goal the task's columns."""
        spec = parse_dataset_name(env)
        assert EFFECTOR_XY + 2 <= ROBOT_COLUMNS
        return Layout(spec.scene_name, act_dim=ACT_DIM, obs_dim=spec.obs_dim, position=EFFECTOR_XY, velocity=None,
                      goal=spec.goal_columns)

    # --- plans -------------------------------------------------------------------------------------------------

    def plan_shape(self, env: str, preset: str) -> tuple[int, int]:
        from bridgeplan.envs.ogbench_manipulation.names import plan_shape

        return plan_shape(env, preset)

    def diffusion_steps(self, env: str) -> int:
        from bridgeplan.envs.ogbench_manipulation.names import DIFFUSION_STEPS

        return DIFFUSION_STEPS

    def longest_span(self, env: str) -> int:
        from bridgeplan.envs.ogbench_manipulation.names import EPISODE_STEPS

        return min(parse_dataset_name(env).scene.eval_steps, EPISODE_STEPS)

    # --- data --------------------------------------------------------------------------------------------------

    def load_stream(self, dataset: str, env: str):
        """The file (checked to be ``env``'s) read by ogbench's loader in its compact form, one segment per episode,
        every row kept (:func:`~bridgeplan.envs.ogbench_data.compact_stream`)."""
        from bridgeplan.envs.ogbench_manipulation.reading import load_dataset

        return compact_stream(load_dataset(dataset, env, compact_dataset=True), env, dataset, self.layout(env))

    # --- evaluation --------------------------------------------------------------------------------------------

    def graph_pace(self, stream, objects: bool = False) -> tuple[dict, None, bool]:
        """:data:`GRAPH` (its radius the scene's where :data:`GRAPH_RADIUS` has one, for the graph over all its objects;
        ``objects``: each part's graph, the family's), the data's median step in the graph's space, its episodes
        apart."""
        radius = GRAPH["radius"] if objects else GRAPH_RADIUS.get(parse_dataset_name(stream.maze).scene_name,
                                                                 GRAPH["radius"])
        return {**GRAPH, "radius": radius}, None, False

    def graph_space(self, stream) -> tuple[tuple[int, ...], float]:
        """The effector's position and the goal's columns (the objects), each standardized over the dataset, the
        objects' weighted by :data:`GRAPH_GOAL_WEIGHT`: what a task moves, and the arm that moves it; the arm's joints,
        velocities and gripper follow from these."""
        return tuple(range(EFFECTOR_XY, EFFECTOR_XY + 3)) + stream.layout.goal, GRAPH_GOAL_WEIGHT

    def graph_objects(self, env: str) -> tuple[tuple[tuple[int, ...], ...], float] | None:
        """The cubes' positions, each done within 0.04 m of its goal (0.4 in the state's units, as ``info["success"]``);
        None where buttons, a drawer or a window are among the goals (a puzzle's buttons toggle one another; scene's
        lock its drawer and window)."""
        scene = parse_dataset_name(env).scene
        if scene.buttons or scene.drawer_window:
            return None
        first = [ROBOT_COLUMNS + CUBE_COLUMNS * i for i in range(scene.cubes)]
        return tuple(tuple(range(c, c + 3)) for c in first), CUBE_TOLERANCE * EFFECTOR_SCALE

    def graph_buttons(self, env: str) -> tuple[tuple[tuple[int, int], ...], int, float] | None:
        """A puzzle's buttons: each one's state (the one-hot's "on" column) and its position (the joint's, times 120),
        the effector's height (its z) and :data:`BUTTON_UP`; None where a goal sets anything else (scene's buttons lock
        its drawer and window)."""
        scene = parse_dataset_name(env).scene
        if not scene.buttons or scene.cubes or scene.drawer_window:
            return None
        first = ROBOT_COLUMNS + CUBE_COLUMNS * scene.cubes
        return tuple((first + BUTTON_COLUMNS * i + 1, first + BUTTON_COLUMNS * i + 2)
                     for i in range(scene.buttons)), EFFECTOR_XY + 2, BUTTON_UP

    def graph_scene(self, env: str) -> SceneParts | None:
        """scene's cube, its two buttons (their one-hots' "on" columns), its drawer and window, each within 0.04 m of
        its goal as ``info["success"]`` counts (in the state's units), each slide locked unless its button is on
        (``SceneEnv._apply_button_states``: button 0 the drawer's, 1 the window's), the cube carried by the drawer."""
        scene = parse_dataset_name(env).scene
        if not (scene.cubes == 1 and scene.buttons == 2 and scene.drawer_window):
            return None
        buttons = ROBOT_COLUMNS + CUBE_COLUMNS
        drawer = buttons + 2 * BUTTON_COLUMNS
        x, y, z = IN_DRAWER
        x = (x[0] - EFFECTOR_CENTRE[0], x[1] - EFFECTOR_CENTRE[0])
        return SceneParts(
            cube=(ROBOT_COLUMNS, ROBOT_COLUMNS + 1, ROBOT_COLUMNS + 2), cube_tolerance=CUBE_TOLERANCE * EFFECTOR_SCALE,
            buttons=(buttons + 1, buttons + BUTTON_COLUMNS + 1), slides=(drawer, drawer + 2),
            slide_tolerances=tuple(SLIDE_TOLERANCE * s for s in SLIDE_SCALES), locks=(0, 1), container=0,
            opened=DRAWER_OPEN * SLIDE_SCALES[0],
            inside=tuple((lo * EFFECTOR_SCALE, hi * EFFECTOR_SCALE) for lo, hi in (x, y, z)),
            carried=(0.0, -EFFECTOR_SCALE / SLIDE_SCALES[0], 0.0))

    def body(self, env: str):
        from bridgeplan.envs.ogbench_manipulation.controllers import body

        return body(self.layout(env))

    def protocol_tasks(self, env: str, episodes: int, seed: int, task_ids: tuple[int, ...] | None):
        from bridgeplan.envs.ogbench_manipulation.protocol import ManipulationTasks

        return ManipulationTasks.make(env, episodes, seed, task_ids)

    def run(self, tasks, agent, progress: bool = False):
        """OGBench's protocol in its own environments, the episodes side by side (:mod:`.protocol`)."""
        from bridgeplan.envs.ogbench_manipulation.protocol import run_tasks

        return run_tasks(tasks, agent, progress)

    def film(self, tasks, agent, size: int):
        """The protocol's run, the first episode's physics states kept and replayed in ogbench's own renderer."""
        from bridgeplan.envs.ogbench_manipulation.protocol import film

        return film(tasks, agent, size)

    def score(self, tasks, outcome) -> dict:
        """The success rate (the mean of the tasks'), the counts, and each task's."""
        d = outcome.to_dict()
        return {"success_rate": d["success_rate"], "successes": d["successes"], "episodes": d["episodes"],
                "tasks": d["tasks"], "protocol_seconds": outcome.seconds}

    def floor_score(self, tasks, outcome) -> dict:
        return {"success_rate": outcome.success_rate, "tasks": {i: t.success_rate for i, t in outcome.tasks.items()}}

    def oracle(self, env: str):
        """Not built: the play oracles plan toward one target at a time in ``data_collection`` mode; a task's several
        targets at once would need a sequencer of their own."""
        raise BridgeplanError(f"{parse_dataset_name(env).name}: OGBench manipulation has no noise-free oracle on its "
                              "evaluation tasks here (its play oracles serve data collection only)")


FAMILY = OGBenchManipulation()
