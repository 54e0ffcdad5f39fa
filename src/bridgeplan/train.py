"""Training: the planner (DDPM or bridge) and the learned prior, with EMA and exact resume; and the one training
loop (:func:`run_steps`: the step budget and time budget, NaN detection, progress, the log and checkpoint cadence)
that they and GCBC/GCIQL (:mod:`bridgeplan.gcbc`) share.

:func:`_fit` serves the planner and the prior: it owns the optimizer, the EMA copy, the RNG, TensorBoard scalars and
checkpoints; :class:`TrainJob` does one optimizer step (the benchmark times that same step). Everything needed to
resume lives in one file, ``RUN/checkpoint.pt``; EMA snapshots ``RUN/snapshots/step_*.pt`` are what the experiments
evaluate across training steps.
"""

from __future__ import annotations

import copy
import json
import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from bridgeplan import config as cfg
from bridgeplan.checkpoint import check_checkpoint_file, load_checkpoint, save_checkpoint, write_config
from bridgeplan.data.windows import hold_tails
from bridgeplan.device import configure_threads, cpu_model, resolve_device
from bridgeplan.errors import BridgeplanError
from bridgeplan.files import check_writable, code_version
from bridgeplan.locks import LOCK_NAME, run_lock
from bridgeplan.paths import checkpoint_path, config_path, snapshot_path, snapshot_steps
from bridgeplan.priors import train_prior_loss
from bridgeplan.progress import progress_bar
from bridgeplan.runs import build_model, build_prior, build_prior_net, load_teacher, load_windows
from bridgeplan.trajectory import window_conditions

# Fields that may change when a run is resumed: they do not change what is being trained.
_RESUMABLE_FIELDS = {"steps", "minutes", "device", "threads", "log_every", "checkpoint_every", "compile"}


@dataclass
class TrainJob:
    """What distinguishes the planner's training from the prior's, and one optimizer step of either."""

    kind: str
    config: object
    model: torch.nn.Module
    loss: Callable[[torch.Tensor, torch.Generator], torch.Tensor]
    normalizer_dict: dict
    grad_accum: int = 1
    ema: tuple[float, int, int] | None = None  # (decay, every, start)

    def accumulate_gradients(self, windows, gen: torch.Generator, device: torch.device) -> torch.Tensor:
        """Draw ``grad_accum`` batches of windows, backpropagate their loss; returns the summed loss as a tensor
        on ``device`` (reading it would make the host wait for the device: the loop checks it every few steps)."""
        total = torch.zeros((), device=device)
        for _ in range(self.grad_accum):
            idx = torch.randint(len(windows), (self.config.batch_size,), generator=gen, device=device)
            with autocast(device, self.config):
                loss = self.loss(windows.batch(idx), gen) / self.grad_accum
            loss.backward()
            total += loss.detach()
        return total

    def apply_gradients(self, optimizer: torch.optim.Optimizer, ema: torch.nn.Module | None, step: int) -> None:
        """The optimizer step, then the EMA update for the new ``step`` count (a copy before ``start``)."""
        optimizer.step()
        optimizer.zero_grad(set_to_none=True)
        if ema is None:
            return
        decay, every, start = self.ema
        if step < start:
            ema.load_state_dict(self.model.state_dict())
        elif step % every == 0:
            with torch.no_grad():
                torch._foreach_lerp_(list(ema.parameters()), list(self.model.parameters()), 1.0 - decay)


def make_optimizer(model: torch.nn.Module, lr: float) -> torch.optim.Optimizer:
    """Adam, fused (one kernel for all parameters) where torch has it for the device: on the small networks
    the per-parameter loop of the plain implementation costs ~10% of a step."""
    device = next(model.parameters()).device
    fused = device.type in ("cpu", "cuda")
    return torch.optim.Adam(model.parameters(), lr=lr, fused=fused)


def _bf16(config) -> bool:
    """Whether ``config`` trains under bfloat16 autocast (the learned prior's config has no such field: fp32)."""
    return getattr(config, "precision", "fp32") == "bf16"


def autocast(device: torch.device, config):
    """The precision ``config`` trains in: bfloat16 autocast for ``bf16``, nothing for ``fp32``."""
    return torch.autocast(device.type, dtype=torch.bfloat16, enabled=_bf16(config))


def make_ema(model: torch.nn.Module) -> torch.nn.Module:
    """The EMA copy of ``model`` (a frozen deep copy; ``TrainJob.apply_gradients`` updates it)."""
    return copy.deepcopy(model).requires_grad_(False)


def train(config: cfg.TrainConfig, run_dir: Path, resume: bool = False, progress: bool = True) -> Path:
    """Train a planner; returns the run directory. See :class:`bridgeplan.config.TrainConfig`."""
    check_run_dir(run_dir, resume, "planner", config)  # before the data is read
    device = _setup(config)
    windows, normalizer = load_windows(config.dataset, config.maze, config.horizon, config.stride)
    return _fit(planner_job(config, normalizer, device), windows.to(device), run_dir, resume, device, progress)


def planner_job(config: cfg.TrainConfig, normalizer, device: torch.device) -> TrainJob:
    """The planner's network (fresh, on ``device``), its loss and EMA settings."""
    teacher = load_teacher(config, normalizer, device)  # None unless the process distills a run
    model = build_model(config).to(device)
    if teacher is not None:  # the student starts as its teacher
        model.load_state_dict(teacher.state_dict())
    net = torch.compile(model) if config.compile else model  # shares model's parameters
    process = config.process
    prior = build_prior(config, normalizer, device)
    against = {} if teacher is None else {"teacher": teacher}
    layout = config.layout
    rest = torch.as_tensor(normalizer.normalize(np.zeros(layout.transition_dim)), dtype=torch.float32, device=device)

    def loss(x0: torch.Tensor, gen: torch.Generator) -> torch.Tensor:
        if config.hold_share:  # drawn only then, so runs without holds keep their random stream
            x0 = hold_tails(x0, config.hold_share, rest, layout, gen)
        conditions = window_conditions(x0, layout, config.subgoal_every)
        x1 = prior.sample(conditions, config.horizon, x0.shape[0], generator=gen)
        return process.training_loss(net, x0, x1, conditions, generator=gen, **against)

    return TrainJob("planner", config, model, loss, normalizer.to_dict(), config.grad_accum,
                    (config.ema_decay, config.ema_every, config.ema_start))


def train_prior(config: cfg.PriorTrainConfig, run_dir: Path, resume: bool = False,
                progress: bool = True) -> Path:
    """Train the learned prior (the thesis's MLP on start and goal) on the same windows and loss."""
    check_run_dir(run_dir, resume, "prior", config)  # before the data is read
    device = _setup(config)
    windows, normalizer = load_windows(config.dataset, config.maze, config.horizon, config.stride)
    net = build_prior_net(config.layout, config.horizon).to(device)
    job = TrainJob("prior", config, net, lambda x0, gen: train_prior_loss(net, x0, config.layout),
                   normalizer.to_dict())
    return _fit(job, windows.to(device), run_dir, resume, device, progress)


def _setup(config) -> torch.device:
    """The device, its threads and the seed; refuses what the device cannot do before anything is written."""
    device = resolve_device(config.device)
    configure_threads(config.threads, device)
    if _bf16(config) and not bf16_supported(device):
        raise BridgeplanError(f"precision bf16 asked for, but {device} has no bfloat16 kernels here "
                              "(train in fp32)")
    if getattr(config, "compile", False):
        check_compiler(device)
    torch.manual_seed(config.seed)  # the network's initial weights
    return device


def loss_check_every(device: torch.device, log_every: int) -> int:
    """Steps between reads of the losses (and before every checkpoint): on a GPU each read makes the host wait for
    the device, so every ``log_every`` steps; on a CPU reading is free, so every step."""
    return 1 if device.type == "cpu" else log_every


def bf16_supported(device: torch.device) -> bool:
    """Whether ``device`` runs bfloat16 convolutions natively (on a CPU: oneDNN with AVX-512 BF16 or AMX)."""
    if device.type == "cuda":
        return torch.cuda.is_bf16_supported()
    if device.type == "cpu":
        return torch.backends.mkldnn.is_available() and torch.ops.mkldnn._is_mkldnn_bf16_supported()
    return False


def check_compiler(device: torch.device) -> None:
    """:class:`BridgeplanError` unless ``torch.compile`` can build kernels for ``device`` here."""
    import shutil

    import torch._dynamo

    if not torch._dynamo.is_dynamo_supported():
        raise BridgeplanError("--compile: torch.compile is not supported on this Python / torch build")
    if device.type == "cpu" and not (shutil.which("c++") or shutil.which("g++") or shutil.which("clang++")):
        raise BridgeplanError("--compile: torch.compile needs a C++ compiler for CPU kernels; none is on PATH")
    if device.type == "cuda":
        try:
            import triton  # noqa: F401
        except ImportError:
            raise BridgeplanError("--compile: torch.compile needs triton for CUDA kernels; it is not installed"
                                  ) from None


def check_resumable(saved: dict, current: dict, path: Path, config_type) -> None:
    """``path`` was trained with ``current`` (a config dict), the fields a resume may change aside (those of
    :data:`_RESUMABLE_FIELDS` and the config type's own ``resumable_too``, wherever a run is checked: on resume and
    for a run killed before its first checkpoint)."""
    resumable = _RESUMABLE_FIELDS | getattr(config_type, "resumable_too", frozenset())

    def canonical(d: dict) -> dict:  # today's form (a run saved by an older bridgeplan too), as JSON has it
        return json.loads(json.dumps(cfg.to_dict(cfg.from_dict(config_type, d))))

    saved, current = canonical(saved), canonical(current)
    diff = sorted(k for k in set(saved) | set(current)
                  if k not in resumable and saved.get(k) != current.get(k))
    if diff:
        detail = ", ".join(f"{k}: {saved.get(k)!r} -> {current.get(k)!r}" for k in diff)
        raise BridgeplanError(f"checkpoint {path} was trained with a different config ({detail})")


def _fit(job: TrainJob, windows, run_dir: Path, resume: bool, device: torch.device, progress: bool) -> Path:
    with run_directory(run_dir, resume, job.kind, job.config):
        return _fit_locked(job, windows, Path(run_dir), resume, device, progress)


@contextmanager
def run_directory(run_dir: Path, resume: bool, kind: str, config) -> Iterator[None]:
    """Hold ``run_dir`` for one trainer of a ``kind`` run of ``config`` (a second one waits for the lock): a mistake
    (:func:`check_run_dir`) refused before the lock creates the directory, so it leaves nothing behind, and again
    once held (another process may have trained it meanwhile); what a killed writer left half-written removed."""
    run_dir = Path(run_dir)
    check_run_dir(run_dir, resume, kind, config)
    with run_lock(run_dir):
        check_run_dir(run_dir, resume, kind, config)
        # whoever wrote these was killed mid-write (a live writer would hold the lock)
        for tmp in [*run_dir.glob(".*.tmp"), *(run_dir / "snapshots").glob(".*.tmp")]:
            tmp.unlink()
        yield


def check_run_dir(run_dir: Path, resume: bool, kind: str, config) -> None:
    """The run directory can be written; --resume needs a checkpoint and snapshots that read whole; a fresh start
    needs an empty directory, or the same run killed before its first checkpoint (nothing to continue; what it left
    is rewritten identically)."""
    run_dir = Path(run_dir)
    check_writable(run_dir, "run directory", folder=True)
    ckpt_path = checkpoint_path(run_dir)
    if ckpt_path.exists():
        if not resume:
            raise BridgeplanError(f"run directory {run_dir} already exists; pass --resume to continue it")
        check_checkpoint_file(ckpt_path)
        for step in snapshot_steps(run_dir):  # a damaged one would be evaluated (or fail) later, not rewritten
            check_checkpoint_file(snapshot_path(run_dir, step), "snapshot")
        return
    killed_early = _same_run(config_path(run_dir), kind, config)
    if resume:
        raise BridgeplanError(f"--resume given but {ckpt_path} does not exist" + (
            " (killed before its first checkpoint: start it again without --resume)" if killed_early else ""))
    if run_dir.exists() and not killed_early and any(not _left_by_a_killed_writer(p) for p in run_dir.iterdir()):
        raise BridgeplanError(f"run directory {run_dir} already exists; pass --resume to continue it")


def _left_by_a_killed_writer(path: Path) -> bool:
    """The lock, or a temporary file of a write killed before it renamed it (e.g. the first config.json's):
    what a run killed before writing its config leaves; the lock holder removes such files."""
    return path.name == LOCK_NAME or (path.is_file() and path.name.startswith(".") and path.name.endswith(".tmp"))


def _same_run(config_json: Path, kind: str, config) -> bool:
    """Whether ``config_json`` describes this training (the fields a resume may change aside)."""
    current = json.loads(json.dumps(cfg.to_dict(config)))  # tuples as JSON has them: lists
    try:
        saved = json.loads(config_json.read_text())
        check_resumable(saved["config"], current, config_json, type(config))
        return saved["kind"] == kind
    except (OSError, ValueError, LookupError, TypeError, AttributeError, BridgeplanError):  # not this run
        return False


def _fit_locked(job: TrainJob, windows, run_dir: Path, resume: bool, device: torch.device,
                progress: bool) -> Path:
    config = job.config
    ckpt_path = checkpoint_path(run_dir)
    config_dict = cfg.to_dict(config)
    model = job.model
    optimizer = make_optimizer(model, config.lr)
    ema = make_ema(model) if job.ema else None
    gen = torch.Generator(device=device).manual_seed(config.seed)
    step, elapsed = 0, 0.0

    if resume:
        state = load_checkpoint(ckpt_path)
        if state["kind"] != job.kind:
            raise BridgeplanError(f"{ckpt_path} is a {state['kind']} checkpoint, not a {job.kind} one")
        check_resumable(state["config"], config_dict, ckpt_path, type(config))
        if state["normalizer"] != job.normalizer_dict:
            raise BridgeplanError(f"{ckpt_path} was trained on a different dataset (normalizer differs)")
        model.load_state_dict(state["model"])
        optimizer.load_state_dict(state["optimizer"])
        if ema is not None:
            ema.load_state_dict(state["ema"])
        gen.set_state(state["generator"].to(gen.get_state().device))
        torch.set_rng_state(state["torch_rng"])
        step, elapsed = state["step"], state["elapsed_seconds"]
    dataset = windows.dataset  # what the data is (Stream.identity), saved beside the config
    write_config(run_dir, {"kind": job.kind, "config": config_dict, "dataset": dataset, "code_version": code_version(),
                           "cpu": cpu_model()})

    def snapshot_state(at: int, seconds: float) -> dict:
        return {"kind": job.kind, "config": config_dict, "normalizer": job.normalizer_dict, "dataset": dataset,
                "step": at, "elapsed_seconds": seconds, "code_version": code_version()}

    def save_snapshot(at: int, seconds: float) -> None:
        weights = (ema if ema is not None else model).state_dict()
        save_checkpoint(snapshot_path(run_dir, at), snapshot_state(at, seconds) | {"ema": weights})

    def save(at: int, seconds: float) -> None:
        # The snapshot first: killed between the two writes, the run resumes from the previous
        # checkpoint and writes this snapshot again (the same weights: resume is exact). In the
        # other order, resume would start after this step and its snapshot would be lost for good.
        save_snapshot(at, seconds)
        save_checkpoint(ckpt_path, snapshot_state(at, seconds) | {
            "model": model.state_dict(), "optimizer": optimizer.state_dict(),
            "ema": ema.state_dict() if ema is not None else None,
            "generator": gen.get_state(), "torch_rng": torch.get_rng_state()})

    if resume and not snapshot_path(run_dir, step).exists():
        save_snapshot(step, elapsed)  # a run written before that order was fixed may lack its checkpoint's snapshot

    writer = _tensorboard(run_dir)

    def one_step(new_step: int) -> torch.Tensor:
        loss = job.accumulate_gradients(windows, gen, device)
        job.apply_gradients(optimizer, ema, new_step)
        return loss

    def log(at: int, rate: float, loss: float, _elapsed: float) -> dict:
        if writer is not None:
            writer.add_scalar("loss", loss, at)
            writer.add_scalar("steps_per_s", rate, at)
        return {"loss": f"{loss:.4f}"}

    model.train()
    try:
        run_steps(step, elapsed, config, one_step, log, save, ckpt_path, device, f"train {run_dir.name}", progress)
    finally:
        if writer is not None:
            writer.close()
    return run_dir


def run_steps(step: int, elapsed: float, config, one_step: Callable[[int], torch.Tensor],
              log: Callable[[int, float, float, float], dict], save: Callable[[int, float], None], ckpt_path: Path,
              device: torch.device, desc: str, progress: bool) -> None:
    """The one training loop of every trained model (a planner, the learned prior, GCBC and GCIQL), from ``step``
    and ``elapsed`` seconds to ``config.steps``, or ``config.minutes`` of training in all: ``one_step(n)`` makes
    the optimizer step that brings the count to ``n`` and returns its loss, unread (reading it makes a GPU's host
    wait: the losses are read every few steps, :func:`loss_check_every`, and before every checkpoint, so that a
    non-finite step is never saved); every ``config.log_every`` steps ``log(step, steps per second, loss,
    elapsed)`` gives the progress bar's fields; every ``config.checkpoint_every`` steps, and at the end,
    ``save(step, elapsed)``. A progress bar named ``desc`` where ``progress``."""
    bar = progress_bar(progress, total=config.steps, initial=step, desc=desc, unit="step", dynamic_ncols=True)
    budget = config.minutes * 60.0 if config.minutes > 0 else math.inf
    last_saved = step
    check_every = loss_check_every(device, config.log_every)
    unchecked: list[torch.Tensor] = []

    def check_losses() -> float:
        """The unchecked steps' losses, read back at once; the first non-finite one stops training."""
        values = torch.stack(unchecked).tolist()
        unchecked.clear()
        for at, value in enumerate(values, start=step - len(values) + 1):
            if not math.isfinite(value):
                raise BridgeplanError(
                    f"loss became {value} at step {at}; stopped. The last good checkpoint "
                    f"(step {last_saved}) is kept in {ckpt_path}" if last_saved else
                    f"loss became {value} at step {at}; stopped before any checkpoint was written")
        return values[-1]

    t_start, t_log, step_log = time.perf_counter(), time.perf_counter(), step
    elapsed0 = elapsed
    try:
        while step < config.steps and elapsed < budget:
            unchecked.append(one_step(step + 1).detach())
            step += 1
            elapsed = elapsed0 + time.perf_counter() - t_start
            bar.update(1)
            log_due, save_due = step % config.log_every == 0, step % config.checkpoint_every == 0
            if len(unchecked) >= check_every or log_due or save_due:
                loss = check_losses()  # before any checkpoint: a non-finite step is never saved
            if log_due:
                now = time.perf_counter()
                rate = (step - step_log) / max(now - t_log, 1e-9)
                t_log, step_log = now, step
                bar.set_postfix(**log(step, rate, loss, elapsed), steps_per_s=f"{rate:.1f}", refresh=False)
            if save_due:
                save(step, elapsed)
                last_saved = step
        if unchecked:
            check_losses()
        if step != last_saved:
            save(step, elapsed)
    finally:
        bar.close()


def _tensorboard(run_dir: Path):
    try:
        from torch.utils.tensorboard import SummaryWriter
    except ImportError:  # tensorboard is an optional extra
        return None
    return SummaryWriter(log_dir=str(run_dir / "tensorboard"))
