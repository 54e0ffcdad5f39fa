"""Pictures: planned and executed trajectories over the maze, prior/target pairs, rollout videos."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from bridgeplan.errors import BridgeplanError
from bridgeplan.files import atomic_write_bytes


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def draw_maze(ax, maze) -> None:
    """Walls as grey squares in gymnasium-robotics coordinates (maze centred on the origin)."""
    from matplotlib.patches import Rectangle

    rows, cols = len(maze.grid), len(maze.grid[0])
    for i in range(rows):
        for j in range(cols):
            if maze.grid[i][j] == 1:
                x, y = j - cols / 2, rows / 2 - i - 1
                ax.add_patch(Rectangle((x, y), 1, 1, color="0.35", lw=0))
    ax.set_xlim(-cols / 2, cols / 2)
    ax.set_ylim(-rows / 2, rows / 2)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])


def draw_path(ax, xy: np.ndarray, cmap: str, label: str | None = None, size: float = 6) -> None:
    """A trajectory as points coloured by time (the thesis's gradients), start and end marked."""
    t = np.linspace(0, 1, len(xy))
    ax.plot(xy[:, 0], xy[:, 1], color="0.6", lw=0.5, zorder=2)
    ax.scatter(xy[:, 0], xy[:, 1], c=t, cmap=cmap, s=size, zorder=3, label=label)
    ax.scatter(*xy[0], marker="o", s=40, facecolor="none", edgecolor="k", zorder=4)
    ax.scatter(*xy[-1], marker="*", s=60, color="k", zorder=4)


def save_figure(fig, path: Path) -> None:
    plt = _pyplot()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=120, bbox_inches="tight")
    plt.close(fig)
    atomic_write_bytes(path, lambda f: f.write(buf.getvalue()))


def plot_trajectory_grid(maze, layers: list[tuple[np.ndarray, str, str]], path: Path, title: str = "",
                         goals: np.ndarray | None = None, columns: int = 4) -> None:
    """One panel per episode; each layer ``(positions [N, T, 2], colormap, label)`` drawn over the maze.

    Used for plans vs executed states (``bridgeplan render``) and prior/target pairs (the thesis's figures).
    """
    plt = _pyplot()
    n = len(layers[0][0])
    rows = (n + columns - 1) // columns
    aspect = len(maze.grid) / len(maze.grid[0])
    fig, axes = plt.subplots(rows, columns, figsize=(3.2 * columns, 3.2 * rows * aspect), squeeze=False)
    for k, ax in enumerate(axes.flat):
        if k >= n:
            ax.axis("off")
            continue
        draw_maze(ax, maze)
        for size, (trajs, cmap, label) in zip((6, 3, 3), layers):
            draw_path(ax, trajs[k], cmap, label, size=size)
        if goals is not None:
            ax.scatter(*goals[k], marker="x", s=80, color="m", zorder=5)
    axes.flat[0].legend(loc="lower left", fontsize=6)
    fig.suptitle(title, fontsize=9)
    save_figure(fig, path)


def render_run(run: Path, episodes: int = 8, nfe: int | None = None, seed: int = 0, multi_task: bool = False,
               out: str | None = None, pairs: bool = False, video: bool = False, device: str = "auto",
               execution=None) -> list[Path]:
    """Plan and execute ``episodes`` episodes of a run and draw them; returns the files written.

    ``execution`` (:class:`~bridgeplan.replan.Execution`): closed loop, candidates, arrival rule; the picture
    then shows each episode's first plan (as executed: chosen, truncated) and the executed states."""
    import torch

    from bridgeplan.envs import family_of
    from bridgeplan.evaluate import PlannerDecisions, generator, run_episodes, run_tasks
    from bridgeplan.paths import render_dir
    from bridgeplan.replan import Execution
    from bridgeplan.runs import load_planner, load_windows
    from bridgeplan.trajectory import window_conditions

    run = Path(run)
    planner, info = load_planner(run, device=device)
    config = info.config
    family = family_of(config.maze)
    if not family.renders:
        raise BridgeplanError(f"{run} is a {family.title} planner: render draws Maze2D's episodes (evaluate it with "
                              f"`bridgeplan eval`)")
    nfe = planner.process.max_nfe if nfe is None else nfe
    planner.process.validate_nfe(nfe)
    tasks = run_tasks(info, episodes, seed, multi_task)
    maze = tasks.maze
    execution = (execution or Execution()).resolved(family, config.maze)
    execution.validate(planner.process, tasks.episode_steps)
    decisions = PlannerDecisions(planner, nfe, execution, family, config.maze)
    first: list[np.ndarray] = []

    class FirstPlans:  # the decisions, keeping each episode's first plan
        device = planner.device

        def source(self, n, gen):
            source = decisions.source(n, gen)

            def decide(states, goals, idx, t):
                planned = source(states, goals, idx, t)
                if t == 0:
                    first.append(planned)
                return planned

            return decide

    result = run_episodes(FirstPlans(), family, tasks, execution).outcome
    plan_states = first[0]
    gen = generator(planner.device, seed)
    tag = f"-{execution.tag()}" if execution.tag() else ""
    base = Path(out) if out else render_dir(info.path) / f"step{info.step}-nfe{nfe}-seed{seed}{tag}.png"
    title = (f"{maze.name}{' Multi2D' if multi_task else ''} {config.label()} NFE={nfe} step={info.step}, "
             f"{execution.tag() or 'open loop'}")
    positions = planner.layout.state_positions
    plot_trajectory_grid(maze, [(positions(plan_states), "winter", "plan" if execution.plans_once else "first plan"),
                                (positions(result.states), "autumn", "executed")],
                         base, title, goals=tasks.goals_xy)
    written = [base]
    if pairs:
        windows, _ = load_windows(config.dataset, config.maze, config.horizon, config.stride)
        idx = torch.randint(len(windows), (episodes,), generator=torch.Generator().manual_seed(seed))
        x0 = windows.batch(idx).to(planner.device)
        with torch.inference_mode():
            x1 = planner.prior.sample(window_conditions(x0, planner.layout), config.horizon, episodes, generator=gen)
        prior_states, _ = planner.unnormalize(x1)
        target_states, _ = planner.unnormalize(x0)
        path = base.with_name(base.stem + "-pairs.png")
        plot_trajectory_grid(maze, [(positions(prior_states), "cool", f"prior ({planner.prior.name})"),
                                    (positions(target_states), "viridis", "target")],
                             path, f"{maze.name}: prior/target pairs")
        written.append(path)
    if video:
        path = base.with_suffix(".gif")
        write_rollout_gif(maze, result.states[0], tasks.goals_xy[0], path)
        written.append(path)
    return written


def write_rollout_gif(maze, states: np.ndarray, goal: np.ndarray, path: Path, every: int = 4) -> None:
    """Replay executed states in MuJoCo's renderer (headless: MUJOCO_GL=egl) and save an animated GIF."""
    from PIL import Image

    from bridgeplan.envs.maze2d.sim import make_gym_env
    from bridgeplan.trajectory import MAZE2D

    env = make_gym_env(maze, render_mode="rgb_array", width=320, height=320)
    env.reset(seed=0)
    point = env.unwrapped.point_env
    env.unwrapped.goal = np.asarray(goal, dtype=np.float64)
    env.unwrapped.update_target_site_pos()
    frames = []
    for s in states[::every]:
        point.set_state(np.asarray(MAZE2D.state_positions(s), dtype=np.float64),
                        np.asarray(MAZE2D.state_velocities(s), dtype=np.float64))
        frames.append(Image.fromarray(env.render()))
    env.close()
    buf = io.BytesIO()
    frames[0].save(buf, format="GIF", save_all=True, append_images=frames[1:], duration=40, loop=0)
    atomic_write_bytes(path, lambda f: f.write(buf.getvalue()))
