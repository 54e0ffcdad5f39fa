"""Pictures of planned and executed episodes, one path for every family that draws them (``Family.picture``):
plans and executed states over the maze (Maze2D's map), or the simulator's own frames of an episode (OGBench's
manipulation); prior/target pairs; a video of an episode (``Family.film``) in MuJoCo's offscreen renderer."""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from bridgeplan.errors import BridgeplanError
from bridgeplan.files import atomic_write_bytes

os.environ.setdefault("MUJOCO_GL", "egl")  # headless unless told otherwise: mujoco reads it when first imported

VIDEO_EVERY = 4
"""A video shows every 4th state of the episode (and its last)."""
CAPTION = 14
"""Pixels of the caption band above a strip of frames."""


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
    columns = min(columns, n)
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


def check_offscreen() -> None:
    """That MuJoCo renders offscreen here (the backend ``MUJOCO_GL`` names), else one BridgeplanError: checked before
    any episode runs, so that nothing is written."""
    try:
        import mujoco

        renderer = mujoco.Renderer(mujoco.MjModel.from_xml_string("<mujoco/>"), 8, 8)
        renderer.render()
        renderer.close()
    except Exception as e:  # each backend fails its own way (ImportError, AttributeError, mujoco.FatalError, ...)
        raise BridgeplanError(f"MuJoCo cannot render offscreen with MUJOCO_GL={os.environ.get('MUJOCO_GL')!r} "
                              f"({type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}): set MUJOCO_GL to "
                              f"egl, or osmesa where OSMesa is installed") from None


def video_steps(length: int, every: int = VIDEO_EVERY) -> list[int]:
    """The states a video of an episode of ``length`` states shows: every ``every``-th, and the last."""
    steps = list(range(0, length, every))
    return steps if steps[-1] == length - 1 else steps + [length - 1]


def strip_steps(length: int) -> list[int]:
    """The states a strip of frames shows: the start, the middle and the end."""
    return [0, (length - 1) // 2, length - 1]


def frame_strip(frames: list[np.ndarray], captions: list[str], title: str) -> bytes:
    """``frames`` side by side under a band of ``title`` and each frame's caption, as PNG bytes."""
    from PIL import Image, ImageDraw, ImageFont

    h, w = frames[0].shape[:2]
    image = Image.new("RGB", (w * len(frames), h + 2 * CAPTION), "white")
    draw = ImageDraw.Draw(image)
    font = ImageFont.load_default(size=CAPTION - 3)
    draw.text((2, 1), title, fill="black", font=font)
    for k, (frame, caption) in enumerate(zip(frames, captions)):
        image.paste(Image.fromarray(frame), (k * w, 2 * CAPTION))
        draw.text((k * w + 2, CAPTION + 1), caption, fill="black", font=font)
    buf = io.BytesIO()
    image.save(buf, format="PNG")
    return buf.getvalue()


def gif(frames: list[np.ndarray], duration_ms: int = 40) -> bytes:
    """``frames`` as an animated GIF, looping."""
    from PIL import Image

    images = [Image.fromarray(f) for f in frames]
    buf = io.BytesIO()
    images[0].save(buf, format="GIF", save_all=True, append_images=images[1:], duration=duration_ms, loop=0)
    return buf.getvalue()


def render_episodes(decisions, family, tasks, execution, base: Path, title: str, video: bool = False,
                    size: int = 240, follower=None) -> list[Path]:
    """Plan and execute ``tasks``' episodes by ``decisions`` (:class:`~bridgeplan.evaluate.Decisions`) as
    ``execution`` says (by ``follower``'s controllers where given: a policy low level's), and draw them as their
    family does (``Family.picture``): ``base`` (PNG), and with ``video``
    ``base`` as a GIF of the first episode, frames ``size`` pixels square. Returns the files written; none is written
    unless every picture was drawn.

    ``map``: one panel per episode, its first plan (as executed: chosen, truncated) and its executed states over the
    maze. ``frames``: the first episode alone is run, and drawn at its start, middle and end as the simulator's camera
    saw it."""
    from bridgeplan.evaluate import run_episodes

    if family.picture is None:
        raise BridgeplanError(f"{family.title} episodes cannot be drawn (evaluate them with `bridgeplan eval`)")
    check_offscreen()
    if family.picture == "frames":
        tasks = tasks.first()
    first: list[np.ndarray] = []
    made: list[tuple[int, np.ndarray]] = []  # (step, plan) of the first episode's plans

    class Kept:  # a batch's decisions, keeping its first plans and, in the first batch, every plan of episode 0
        def __init__(self, source, batch: int):
            self.inner, self.batch = source, batch
            self.step_ends = getattr(source, "step_ends", None)  # paths made of steps: where each first step ends

        def __call__(self, states, goals, idx, t):
            planned = self.inner(states, goals, idx, t)
            if t == 0:
                first.append(planned)
            if self.batch == 0 and 0 in idx:
                made.append((t, planned[list(idx).index(0)]))
            return planned

    class FirstPlans:  # the decisions, each batch's kept
        device = decisions.device

        def source(self, n, gen):
            return Kept(decisions.source(n, gen), len(first))

    def in_force(steps: list[int]) -> list[np.ndarray | None]:
        """The first episode's plan at each of ``steps``: the last made at or before it."""
        return [next((plan for t, plan in reversed(made) if t <= k), None) for k in steps]

    episodes = run_episodes(FirstPlans(), family, tasks, execution,
                            run=lambda t, agent, progress: family.film(t, agent, size), follower=follower)
    outcome, film = episodes.outcome
    steps = video_steps(film.length)
    movie = gif(film.frames(steps, in_force(steps))) if video else None
    if family.picture == "map":
        positions = family.layout(tasks.env).state_positions
        plot_trajectory_grid(tasks.maze, [(positions(first[0]), "winter",
                                           "plan" if execution.plans_once else "first plan"),
                                          (positions(outcome.states), "autumn", "executed")],
                             base, title, goals=tasks.goals_xy)
    else:
        steps = strip_steps(film.length)
        captions = ["start", f"step {steps[1]}", f"end, step {steps[2]}: {film.outcome}"]
        png = frame_strip(film.frames(steps, in_force(steps)), captions,
                          f"{title}, seed {tasks.seed}; blue: the plan in force")
        atomic_write_bytes(base, lambda f: f.write(png))
    written = [base]
    if movie is not None:
        path = base.with_suffix(".gif")
        atomic_write_bytes(path, lambda f: f.write(movie))
        written.append(path)
    return written


def render_run(run: Path, episodes: int = 8, nfe: int | None = None, seed: int = 0, multi_task: bool = False,
               task_ids: tuple[int, ...] | None = None, out: str | None = None, pairs: bool = False,
               video: bool = False, size: int = 240, device: str = "auto", execution=None) -> list[Path]:
    """Plan and execute ``episodes`` episodes of a run and draw them (:func:`render_episodes`); returns the files
    written.

    ``execution`` (:class:`~bridgeplan.replan.Execution`): closed loop, candidates, arrival rule; a map then shows each
    episode's first plan (as executed: chosen, truncated) and the executed states."""
    import torch

    from bridgeplan.envs import FAMILIES, family_of
    from bridgeplan.evaluate import PlannerDecisions, generator, run_tasks
    from bridgeplan.paths import render_dir
    from bridgeplan.replan import Execution
    from bridgeplan.runs import load_planner, load_windows
    from bridgeplan.trajectory import window_conditions

    run = Path(run)
    planner, info = load_planner(run, device=device)
    config = info.config
    family = family_of(config.maze)
    if family.picture is None:
        drawn = " and ".join(f"{f.title}'s" for f in FAMILIES if f.picture)
        raise BridgeplanError(f"{run} is a {family.title} planner: render draws {drawn} episodes (evaluate it with "
                              f"`bridgeplan eval`)")
    if pairs and family.picture != "map":
        raise BridgeplanError(f"--pairs draws prior/target pairs over a map: {family.title} has none")
    nfe = planner.process.max_nfe if nfe is None else nfe
    planner.process.validate_nfe(nfe)
    tasks = run_tasks(info, episodes, seed, multi_task, task_ids)
    execution = (execution or Execution()).resolved(family, config.maze)
    execution.validate(planner.process, tasks.episode_steps)
    decisions = PlannerDecisions(planner, nfe, execution, family, config.maze)
    tag = f"-{execution.tag()}" if execution.tag() else ""
    base = Path(out) if out else render_dir(info.path) / f"step{info.step}-nfe{nfe}-seed{seed}{tag}.png"
    title = (f"{family.label(config.maze)}{' Multi2D' if multi_task else ''} {config.label()} NFE={nfe} "
             f"step={info.step}, {execution.tag() or 'open loop'}")
    written = render_episodes(decisions, family, tasks, execution, base, title, video, size)
    if pairs:
        gen = generator(planner.device, seed)
        windows, _ = load_windows(config.dataset, config.maze, config.horizon, config.stride)
        idx = torch.randint(len(windows), (episodes,), generator=torch.Generator().manual_seed(seed))
        x0 = windows.batch(idx).to(planner.device)
        with torch.inference_mode():
            x1 = planner.prior.sample(window_conditions(x0, planner.layout), config.horizon, episodes, generator=gen)
        prior_states, _ = planner.unnormalize(x1)
        target_states, _ = planner.unnormalize(x0)
        path = base.with_name(base.stem + "-pairs.png")
        positions = planner.layout.state_positions
        plot_trajectory_grid(tasks.maze, [(positions(prior_states), "cool", f"prior ({planner.prior.name})"),
                                          (positions(target_states), "viridis", "target")],
                             path, f"{tasks.maze.name}: prior/target pairs")
        written.append(path)
    return written
