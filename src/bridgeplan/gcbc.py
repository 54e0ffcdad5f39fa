"""Goal-conditioned behaviour cloning (GCBC) on OGBench datasets: the calibration baseline (pointmaze, manipulation);
its training (``train_gcbc``, on the one loop of every trained model, ``train.run_steps``) also trains GCIQL
(``GCBCConfig.agent``, :mod:`bridgeplan.gciql`), whose actor is the same policy.

What OGBench does (``impls/agents/gcbc.py``, ``impls/utils/datasets.py`` ``GCDataset``, ``impls/main.py``),
re-implemented in PyTorch:

- the dataset is read as OGBench's training script reads it, *compact* (``ogbench.utils.load_dataset(...,
  compact_dataset=True)``): the last state of every trajectory is not a valid sample (it has no action
  followed by a next state) and, as a consequence of how OGBench marks trajectory ends in that form, is
  never a goal either: a trajectory's "final state" is its second-to-last;
- a batch is ``batch_size`` uniform draws among the valid states; each gets a goal (:meth:`GoalDataset.sample_goals`):
  with probability ``p_curgoal`` the state itself, with ``p_trajgoal`` a future state of the same trajectory,
  with ``p_randomgoal`` a random valid state of the dataset. The future state is uniform on ``[t + 1, final]``
  (OGBench's rounding of a uniform mix, so both ends carry half weight) or, with ``geom_sample``,
  ``min(t + k, final)`` with ``k ~ Geometric(1 - discount)``. GCBC's defaults: always a future state, uniform;
- the loss is the negative log-likelihood of the dataset's action under the policy's Gaussian
  (:class:`bridgeplan.nets.policy.GoalPolicy`: constant std 1, so regression of the mean); Adam, lr 3e-4,
  batch 1024, 1 M steps, no EMA, no observation normalisation;
- evaluation acts with the mean clipped to ``[-1, 1]`` (temperature 0): :meth:`GCBCPolicy.act`.

The random stream differs from OGBench's (numpy's ``Generator`` here, seeded from ``seed`` and saved in
every checkpoint so a resumed run continues the same stream); the distributions are the same.

On disk (:mod:`bridgeplan.paths`): ``RUN/checkpoint.pt`` resumes everything, ``RUN/config.json`` is the
config beside it, ``RUN/snapshots/step_*.pt`` the policy's weights at every ``checkpoint_every`` steps (what
evaluation loads), ``RUN/metrics.jsonl`` one line per ``log_every`` steps (loss, MSE, steps/s).
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import json
import math
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import torch

from bridgeplan import config as cfg
from bridgeplan.checkpoint import load_checkpoint, save_checkpoint, write_config
from bridgeplan.device import configure_threads, cpu_model, resolve_device
from bridgeplan.envs import family_of
from bridgeplan.envs.ogbench_pointmaze.names import dataset_env as environment
from bridgeplan.errors import BridgeplanError, check_choice
from bridgeplan.files import code_version
from bridgeplan.nets.policy import GoalPolicy, unit_gaussian_nll
from bridgeplan.paths import checkpoint_path, snapshot_path, snapshot_steps
from bridgeplan.train import check_resumable, check_run_dir, make_optimizer, run_directory, run_steps

KIND = "gcbc"
AGENTS = ("gcbc", "gciql")
METRICS_NAME = "metrics.jsonl"


@dataclass(frozen=True)
class GCBCConfig:
    """One GCBC training run. Defaults are OGBench's for pointmaze (``impls/agents/gcbc.py``,
    ``impls/main.py``; ``impls/hyperparameters.sh`` passes no GCBC overrides for pointmaze)."""

    resumable_too: ClassVar[frozenset] = frozenset({"dataset"})
    """What a resumed run may change beyond a planner's (``train.check_resumable``): the dataset's path (a moved
    file); its content is checked instead, by fingerprint."""

    dataset: str = ""
    """Path to the training npz in OGBench's format (``observations``, ``actions``, ``terminals``)."""
    maze: str = ""
    """The OGBench environment the data is of: a dataset name (``pointmaze-medium-navigate-v0``,
    ``cube-single-play-v0``) or a bare pointmaze maze (``medium``, as earlier runs name it): the file is checked to be
    one (its family's ``dataset_info``) and evaluation defaults to it. Empty: any OGBench-format file, unchecked."""
    lr: float = 3e-4
    """Adam's learning rate (OGBench: 3e-4)."""
    batch_size: int = 1024
    """Transitions per step (OGBench: 1024)."""
    hidden_dims: tuple[int, ...] = (512, 512, 512)
    """The policy MLP's hidden layer widths (OGBench: 512, 512, 512)."""
    steps: int = 1_000_000
    """Optimizer steps (OGBench: 1 M; a CPU core affords a few tens of thousands an hour, see the README)."""
    minutes: float = 0.0
    """Wall-clock budget in minutes across resumes (0: none); training stops at ``steps`` or this, first."""
    p_curgoal: float = 0.0
    """Probability that the goal is the current state (OGBench's ``actor_p_curgoal``: 0)."""
    p_trajgoal: float = 1.0
    """Probability that the goal is a future state of the same trajectory (``actor_p_trajgoal``: 1)."""
    p_randomgoal: float = 0.0
    """Probability that the goal is a random state of the dataset (``actor_p_randomgoal``: 0)."""
    geom_sample: bool = False
    """Future goals at a Geometric(1 - discount) offset instead of uniform (``actor_geom_sample``: False)."""
    discount: float = 0.99
    """Only used by ``geom_sample`` (OGBench: 0.99)."""
    seed: int = 0
    """Seeds the initial weights and the sampling stream."""
    checkpoint_every: int = 100_000
    """Steps between checkpoints and policy snapshots (OGBench evaluates every 100 k steps)."""
    log_every: int = 5_000
    """Steps between lines of ``metrics.jsonl`` (OGBench logs every 5 k steps)."""
    device: str = "auto"
    threads: int = 0
    """Torch CPU threads (0: one on a CPU device, see :func:`bridgeplan.device.configure_threads`)."""
    agent: str = "gcbc"
    """What is trained: ``gcbc`` (the policy alone) or ``gciql`` (:mod:`bridgeplan.gciql`: a value, critics and the
    policy as their actor; the GCIQL fields are its, defaults OGBench's ``impls/agents/gciql.py``)."""
    alpha: float = 0.3
    """GCIQL: the behaviour-cloning weight of the DDPG+BC actor (OGBench 0.3; hyperparameters.sh: 1.0 on every
    manipulation dataset, 0.003 on pointmaze)."""
    expectile: float = 0.9
    """GCIQL: the value's expectile."""
    tau: float = 0.005
    """GCIQL: the slow critics' Polyak rate."""
    value_p_curgoal: float = 0.2
    """GCIQL: probability that the value's goal is the current state (``value_p_curgoal``)."""
    value_p_trajgoal: float = 0.5
    """GCIQL: ... a future state of the same trajectory, at a Geometric(1 - discount) offset (``value_geom_sample``)."""
    value_p_randomgoal: float = 0.3
    """GCIQL: ... a random state of the dataset."""
    layer_norm: bool = True
    """GCIQL: layer normalization in the value and the critics."""

    def __post_init__(self):
        cfg.check_optimization(self)
        check_choice("agent", self.agent, AGENTS)
        value = (self.value_p_curgoal, self.value_p_trajgoal, self.value_p_randomgoal)
        if min(value) < 0 or not math.isclose(sum(value), 1.0):
            raise BridgeplanError(f"value goal probabilities (current, trajectory, random) must be >= 0 and sum to 1, "
                                  f"got {value}")
        if not (0.5 <= self.expectile < 1 and 0 < self.tau <= 1 and self.alpha >= 0 and 0 < self.discount < 1):
            raise BridgeplanError(f"GCIQL needs expectile in [0.5, 1), tau in (0, 1], alpha >= 0 and discount in "
                                  f"(0, 1), got {self.expectile}, {self.tau}, {self.alpha}, {self.discount}")
        if not self.hidden_dims or min(self.hidden_dims) <= 0:
            raise BridgeplanError(f"hidden_dims must be positive widths, got {self.hidden_dims}")
        probs = (self.p_curgoal, self.p_trajgoal, self.p_randomgoal)
        if min(probs) < 0 or not math.isclose(sum(probs), 1.0):
            raise BridgeplanError(f"goal probabilities (current, trajectory, random) must be >= 0 and sum to 1, "
                                  f"got {probs}")
        if self.geom_sample and not 0 < self.discount < 1:
            raise BridgeplanError(f"discount must be in (0, 1) for geometric goal sampling, got {self.discount}")


class GoalDataset:
    """An OGBench dataset in compact form with GCBC's batches: states, actions and goals, sampled on the host."""

    def __init__(self, path: str | Path, p_curgoal: float = 0.0, p_trajgoal: float = 1.0,
                 p_randomgoal: float = 0.0, geom_sample: bool = False, discount: float = 0.99, maze: str = ""):
        self.path = Path(path)
        if maze:
            env = environment(maze)
            family_of(env).dataset_info(str(self.path), env)  # the file checked to be of its environment
        self.p_curgoal, self.p_trajgoal, self.p_randomgoal = p_curgoal, p_trajgoal, p_randomgoal
        self.geom_sample, self.discount = geom_sample, discount
        data = _load_compact(self.path)
        self.observations: np.ndarray = data["observations"]
        self.actions: np.ndarray = data["actions"]
        (self.valid_idxs,) = np.nonzero(data["valids"] > 0)
        (self.terminal_locs,) = np.nonzero(data["terminals"] > 0)
        if len(self.valid_idxs) == 0:
            raise BridgeplanError(f"{self.path} has no transition (every trajectory is a single state)")

    @classmethod
    def for_config(cls, config: GCBCConfig, path: str | Path | None = None) -> GoalDataset:
        return cls(path if path is not None else config.dataset, config.p_curgoal, config.p_trajgoal,
                   config.p_randomgoal, config.geom_sample, config.discount, config.maze)

    @property
    def obs_dim(self) -> int:
        return self.observations.shape[1]

    @property
    def action_dim(self) -> int:
        return self.actions.shape[1]

    def fingerprint(self) -> dict[str, Any]:
        """What identifies the data a run was trained on (a resume must see the same)."""
        digest = hashlib.sha256(self.observations.tobytes())
        digest.update(self.actions.tobytes())
        return {"size": int(len(self.observations)), "sha256": digest.hexdigest()[:16]}

    def random_idxs(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` uniform draws among the valid states (every state but each trajectory's last)."""
        return self.valid_idxs[rng.integers(len(self.valid_idxs), size=n)]

    def sample_goals(self, idxs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The goal index for each state index, as OGBench's ``GCDataset.sample_goals`` draws it."""
        n = len(idxs)
        random_goals = self.random_idxs(n, rng)
        final = self.terminal_locs[np.searchsorted(self.terminal_locs, idxs)]  # this trajectory's final state
        if self.geom_sample:
            traj_goals = np.minimum(idxs + rng.geometric(1.0 - self.discount, size=n), final)
        else:
            u = rng.random(n)  # in [0, 1): from final (u = 0) down to the next state (u -> 1)
            traj_goals = np.round(np.minimum(idxs + 1, final) * u + final * (1.0 - u)).astype(np.int64)
        if self.p_curgoal == 1.0:
            return idxs.copy()
        goals = np.where(rng.random(n) < self.p_trajgoal / (1.0 - self.p_curgoal), traj_goals, random_goals)
        return np.where(rng.random(n) < self.p_curgoal, idxs, goals)

    def sample(self, batch_size: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """A batch's indices: ``(states, goals)``; a state's index is also its action's."""
        idxs = self.random_idxs(batch_size, rng)
        return idxs, self.sample_goals(idxs, rng)


def _load_compact(path: Path) -> dict[str, np.ndarray]:
    """OGBench's compact form of the npz at ``path``, with its mistakes reported as :class:`BridgeplanError`."""
    if not path.is_file():
        raise BridgeplanError(f"no dataset file at {path}")
    try:
        with np.load(path) as f:
            missing = [k for k in ("observations", "actions", "terminals") if k not in f.files]
            raw_terminals = f["terminals"][...] if not missing else None
    except (OSError, ValueError, zipfile.BadZipFile) as e:
        raise BridgeplanError(f"cannot read dataset {path} (not an npz?): {e}") from None
    if missing:
        raise BridgeplanError(f"{path} lacks {', '.join(missing)} (OGBench's npz format)")
    if len(raw_terminals) == 0 or not raw_terminals[-1]:
        raise BridgeplanError(f"{path}: the last step must end a trajectory (terminals[-1] = 1)")
    try:
        from ogbench.utils import load_dataset
    except ImportError:
        raise BridgeplanError("reading OGBench datasets needs the ogbench package (pip install ogbench)") from None
    data = load_dataset(str(path), compact_dataset=True)
    obs, act = data["observations"], data["actions"]
    if obs.ndim != 2 or act.ndim != 2 or not len(obs) == len(act) == len(data["terminals"]):
        raise BridgeplanError(f"{path}: observations {obs.shape}, actions {act.shape} and terminals "
                              f"{data['terminals'].shape} must be [N, d], [N, a], [N]")
    return data


class _GCBCStep:
    """GCBC's step: the data's action's NLL under the policy, goals as ``GCBCConfig`` draws them."""

    columns = ("loss", "mse")

    def __init__(self, config: GCBCConfig, data: GoalDataset, device: torch.device):
        self.config, self.data = config, data
        self.net = self.policy = build_policy(config, data.obs_dim, data.action_dim).to(device)

    def trained(self) -> torch.nn.Module:
        return self.net

    def loss(self, obs: torch.Tensor, actions: torch.Tensor, rng: np.random.Generator):
        idx, goal_idx = self.data.sample(self.config.batch_size, rng)
        idx_t, goal_t = torch.from_numpy(idx).to(obs.device), torch.from_numpy(goal_idx).to(obs.device)
        mean, a = self.net(obs[idx_t], obs[goal_t]), actions[idx_t]
        loss = unit_gaussian_nll(mean, a).mean()
        return loss, torch.stack([loss.detach(), (mean - a).square().mean().detach()])  # OGBench's "mse" too

    def after_step(self) -> None:
        pass


class _GCIQLStep:
    """GCIQL's step (:class:`bridgeplan.gciql.GCIQL`): the value's goals and the actor's drawn apart, the state after
    each one (its index + 1: a valid state is never a trajectory's last), rewards from the goals' indices."""

    columns = ("loss", "value_loss", "critic_loss", "actor_loss", "mse")

    def __init__(self, config: GCBCConfig, data: GoalDataset, device: torch.device):
        from bridgeplan.gciql import GCIQL

        self.config, self.data = config, data
        self.value_goals = copy.copy(data)
        self.value_goals.p_curgoal, self.value_goals.p_trajgoal, self.value_goals.p_randomgoal = (
            config.value_p_curgoal, config.value_p_trajgoal, config.value_p_randomgoal)
        self.value_goals.geom_sample = True
        self.net = GCIQL(data.obs_dim, data.action_dim, config.hidden_dims, config.layer_norm).to(device)
        self.policy = self.net.actor

    def trained(self) -> torch.nn.Module:
        """What the optimizer moves (the slow critics follow by ``update_target``)."""
        return torch.nn.ModuleList([self.net.actor, self.net.value, self.net.critic])

    def loss(self, obs: torch.Tensor, actions: torch.Tensor, rng: np.random.Generator):
        c = self.config
        idx = self.data.random_idxs(c.batch_size, rng)
        value_goal = self.value_goals.sample_goals(idx, rng)
        actor_goal = self.data.sample_goals(idx, rng)
        reached = torch.from_numpy((idx == value_goal).astype(np.float32)).to(obs.device)
        i, vg, ag = (torch.from_numpy(v).to(obs.device) for v in (idx, value_goal, actor_goal))
        loss, logged = self.net.loss(obs[i], obs[i + 1], actions[i], obs[vg], obs[ag], reached - 1.0, 1.0 - reached,
                                     c.discount, c.expectile, c.alpha)
        return loss, torch.cat([loss.detach()[None], logged])

    def after_step(self) -> None:
        self.net.update_target(self.config.tau)


def build_policy(config: GCBCConfig, obs_dim: int, action_dim: int) -> GoalPolicy:
    """The policy network for ``config`` (goals are full observations, as in OGBench's state-based tasks)."""
    return GoalPolicy(obs_dim, obs_dim, action_dim, config.hidden_dims)


class GCBCPolicy:
    """A trained GCBC policy behind the batched interface evaluation uses: numpy in, numpy out."""

    def __init__(self, net: GoalPolicy, step: int, config: GCBCConfig, device: torch.device,
                 dataset_identity: str = "", elapsed_seconds: float | None = None):
        self.net, self.step, self.config, self.device = net.eval(), step, config, device
        self.elapsed_seconds = elapsed_seconds
        """Wall-clock seconds the run had trained at this step (None where its file does not say)."""
        self.dataset_identity = dataset_identity
        """A shipped policy's: the identity of the data its scores' graph was built over (else empty)."""

    @property
    def env(self) -> str | None:
        """The environment the policy was trained for (None: its run named none)."""
        return trained_env(self.config.maze)

    @property
    def dataset(self) -> str:
        """Its training data: the run's file, or for a shipped policy (its config names the file alone) where
        ``bridgeplan data generate`` puts that dataset on this machine."""
        if self.dataset_identity and self.env is not None:
            return family_of(self.env).default_dataset(self.env, 0)
        return self.config.dataset

    def act(self, observations: np.ndarray, goals: np.ndarray) -> np.ndarray:
        """Actions ``[N, a]`` (the mean, clipped to [-1, 1]) for observations and goals ``[N, d]``."""
        obs = torch.as_tensor(np.asarray(observations, dtype=np.float32), device=self.device)
        goal = torch.as_tensor(np.asarray(goals, dtype=np.float32), device=self.device)
        return self.net.act(obs, goal).cpu().numpy()


def load_policy(path: str | Path, device: str = "cpu") -> GCBCPolicy:
    """The policy of a GCBC run directory (its latest checkpoint), of one snapshot file or a shipped policy's name."""
    from bridgeplan.runs import resolve_run

    state = load_checkpoint(resolve_run(path))
    if state["kind"] != KIND:
        raise BridgeplanError(f"{path} is a {state['kind']} checkpoint, not a GCBC one")
    config = cfg.from_dict(GCBCConfig, state["config"])
    dev = resolve_device(device)
    net = build_policy(config, state["obs_dim"], state["action_dim"]).to(dev)
    net.load_state_dict(state["policy"])
    return GCBCPolicy(net, state["step"], config, dev, state.get("dataset_identity", ""),
                      state.get("elapsed_seconds"))


def trained_env(maze: str) -> str | None:
    """The environment of a GCBC config's ``maze`` (earlier runs name a bare pointmaze maze; None: none named)."""
    return environment(maze) if maze else None


def run_env_and_dataset(run_dir: str | Path) -> tuple[str | None, str]:
    """A GCBC run's environment (:func:`trained_env`) and training data, from its ``config.json`` (a shipped
    policy's: :attr:`GCBCPolicy.dataset`)."""
    from bridgeplan.paths import config_path

    if _shipped(run_dir) is not None:
        policy = load_policy(run_dir)
        return policy.env, policy.dataset
    trained = json.loads(config_path(run_dir).read_text())["config"]
    return trained_env(trained["maze"]), trained["dataset"]


def _shipped(run: str | Path):
    """The shipped policy named ``run`` (:mod:`bridgeplan.shipped`), when no path of that name exists."""
    from bridgeplan import shipped

    entry = None if Path(run).exists() else shipped.get(str(run))
    return entry if entry is not None and entry.kind == "policy" else None


def is_gcbc_run(path: str | Path) -> bool:
    """Whether ``path`` is a GCBC run directory (its ``config.json`` says so) or a shipped policy's name."""
    from bridgeplan.paths import config_path

    if _shipped(path) is not None:
        return True
    config = config_path(path)
    try:
        return Path(path).is_dir() and json.loads(config.read_text()).get("kind") == KIND
    except (OSError, ValueError):
        return False


def policy_path(run_dir: str | Path, step: int | None = None) -> Path:
    """Run ``run_dir``'s latest checkpoint (``step`` None) or its policy snapshot at ``step``; a shipped policy's
    file (its one step)."""
    entry = _shipped(run_dir)
    if entry is not None:
        from bridgeplan.shipped import verified_path

        if step is not None and step != entry.step:
            raise BridgeplanError(f"shipped policy {entry.name!r} has the weights of step {entry.step} only, not "
                                  f"step {step}")
        return verified_path(entry)
    if step is None:
        return checkpoint_path(run_dir)
    available = dict(policy_snapshots(run_dir))
    if step not in available:
        raise BridgeplanError(f"{run_dir} has no snapshot at step {step} (it has: "
                              f"{', '.join(map(str, available)) or 'none'})")
    return available[step]


def policy_snapshots(run_dir: str | Path) -> list[tuple[int, Path]]:
    """``(step, path)`` of every policy snapshot of a run, ascending."""
    return [(s, snapshot_path(run_dir, s)) for s in snapshot_steps(run_dir)]


def train_gcbc(config: GCBCConfig, run_dir: str | Path, resume: bool = False, progress: bool = True) -> Path:
    """Train GCBC into ``run_dir`` (a fresh directory, or a run to continue with ``resume``: refused as a planner's
    run is, ``train.run_directory``); returns it.

    A resumed run continues exactly: N steps in one go and N/2 + N/2 across a resume give the same weights.
    """
    run_dir = Path(run_dir)
    check_run_dir(run_dir, resume, KIND, config)  # before the data is read
    device = resolve_device(config.device)
    data = GoalDataset.for_config(config)
    with run_directory(run_dir, resume, KIND, config):
        configure_threads(config.threads, device)
        return _train_locked(config, data, run_dir, resume, device, progress)


def _train_locked(config: GCBCConfig, data: GoalDataset, run_dir: Path, resume: bool, device: torch.device,
                  progress: bool) -> Path:
    ckpt = checkpoint_path(run_dir)
    config_dict = cfg.to_dict(config)
    fingerprint = data.fingerprint()
    torch.manual_seed(config.seed)  # the initial weights
    learner = (_GCIQLStep if config.agent == "gciql" else _GCBCStep)(config, data, device)
    net = learner.net
    optimizer = make_optimizer(learner.trained(), config.lr)
    rng = np.random.default_rng(config.seed)
    step, elapsed = 0, 0.0
    # the logged columns summed since the log line at step log_from (saved: a resumed run writes the same lines)
    sums, log_from = torch.zeros(len(learner.columns), device=device), 0
    if resume:
        state = load_checkpoint(ckpt)
        if state["kind"] != KIND:
            raise BridgeplanError(f"{ckpt} is a {state['kind']} checkpoint, not a GCBC one")
        check_resumable(state["config"], config_dict, ckpt, GCBCConfig)
        if state["dataset"] != fingerprint:
            raise BridgeplanError(f"{ckpt} was trained on different data than {config.dataset}")
        net.load_state_dict(state.get("agent", state["policy"]))
        optimizer.load_state_dict(state["optimizer"])
        rng.bit_generator.state = state["rng"]
        step, elapsed = state["step"], state["elapsed_seconds"]
        sums.copy_(state["log_sums"])
        log_from = state["log_from"]
    write_config(run_dir, {"kind": KIND, "config": config_dict, "code_version": code_version(), "cpu": cpu_model()})
    metrics = _Metrics(run_dir / METRICS_NAME, keep_until=step)

    obs = torch.as_tensor(data.observations, device=device)
    actions = torch.as_tensor(data.actions, device=device)

    def snapshot_state(at: int, seconds: float) -> dict:
        return {"kind": KIND, "config": config_dict, "dataset": fingerprint, "obs_dim": data.obs_dim,
                "action_dim": data.action_dim, "step": at, "elapsed_seconds": seconds,
                "code_version": code_version(), "policy": learner.policy.state_dict()}

    def save(at: int, seconds: float) -> None:
        # the snapshot first: killed between the writes, the resumed run rewrites it (identically)
        save_checkpoint(snapshot_path(run_dir, at), snapshot_state(at, seconds))
        agent = {"agent": net.state_dict()} if net is not learner.policy else {}  # the critics too, to resume
        save_checkpoint(ckpt, snapshot_state(at, seconds) | agent | {
            "optimizer": optimizer.state_dict(), "rng": rng.bit_generator.state, "log_sums": sums.cpu(),
            "log_from": log_from})

    def one_step(_new_step: int) -> torch.Tensor:
        loss, logged = learner.loss(obs, actions, rng)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        learner.after_step()
        with torch.no_grad():
            sums.add_(logged)
        return loss

    def log(at: int, rate: float, _loss: float, seconds: float) -> dict:
        nonlocal log_from
        means = dict(zip(learner.columns, (sums / (at - log_from)).tolist()))
        log_from = at
        sums.zero_()
        metrics.write({"step": at, **means, "steps_per_s": rate, "elapsed_seconds": seconds})
        return {"loss": f"{means['loss']:.4f}", "mse": f"{means['mse']:.4f}"}

    net.train()
    try:
        run_steps(step, elapsed, config, one_step, log, save, ckpt, device, f"train {config.agent}", progress)
    finally:
        metrics.close()
    return run_dir


class _Metrics:
    """``metrics.jsonl``: one JSON line per log; a resumed run drops the lines after its checkpoint's step
    (the killed run's lines that training repeats)."""

    def __init__(self, path: Path, keep_until: int):
        lines = path.read_text().splitlines() if path.exists() and keep_until > 0 else []
        kept = [ln for ln in lines if ln.strip() and json.loads(ln)["step"] <= keep_until]
        path.write_text("".join(ln + "\n" for ln in kept))
        self._file = path.open("a")

    def write(self, row: dict) -> None:
        self._file.write(json.dumps(row) + "\n")
        self._file.flush()

    def close(self) -> None:
        self._file.close()


def read_metrics(run_dir: str | Path) -> list[dict]:
    """The rows of a run's ``metrics.jsonl``."""
    path = Path(run_dir) / METRICS_NAME
    return [json.loads(ln) for ln in path.read_text().splitlines() if ln.strip()] if path.exists() else []


@dataclass
class GoalDecisions:
    """A goal-conditioned policy's decisions: each episode's goal, a plan of one state made when the episode starts
    (and again when its goal moves), which :class:`~bridgeplan.envs.controllers.PolicyFollower` pursues with the
    policy at every step (its network calls counted there)."""

    device: torch.device

    def source(self, n: int, generator: torch.Generator | None = None):
        return lambda states, goals, episodes, t: np.asarray(goals, np.float64)[:, None, :]


def run_policy(run: str | Path, snapshot: int | None = None, device: str = "cpu", env: str | None = None) -> GCBCPolicy:
    """The policy of GCBC/GCIQL run ``run`` (its ``snapshot`` step, default its latest checkpoint) for ``env``
    (default: the run's own), whose observations must be the policy's."""
    policy = load_policy(policy_path(run, snapshot), device)
    env = env or policy.env
    if env is None:
        raise BridgeplanError(f"{run} was trained without --maze: name the environment its data is of "
                              f"(`bridgeplan graph --maze NAME --low {run}`)")
    obs_dim = family_of(env).layout(env).obs_dim
    if policy.net.obs_dim != obs_dim:
        raise BridgeplanError(f"{run} was trained on {policy.net.obs_dim}-D observations, {env}'s are {obs_dim}-D")
    return policy


def evaluate_policy(run: str | Path, episodes: int | None = None, seed: int = 0, multi_task: bool = False,
                    task_ids: tuple[int, ...] | None = None, snapshot: int | None = None, device: str = "cpu",
                    progress: bool = False):
    """A GCBC/GCIQL run's policy (its ``snapshot``, default its latest checkpoint) on its environment's tasks, as
    every evaluation (:func:`bridgeplan.evaluate.evaluate`): the goal its decision, the policy its controller. The
    row names the run, its dataset (by name: no path of this machine), its training seed and time."""
    from bridgeplan.envs.controllers import PolicyFollower
    from bridgeplan.evaluate import evaluate, make_tasks
    from bridgeplan.replan import Execution

    policy = run_policy(run, snapshot, device)
    env, family = policy.env, family_of(policy.env)
    tasks = make_tasks(env, episodes, seed, multi_task, task_ids)
    dataset = Path(policy.config.dataset).stem
    entries = {"run": Path(run).name, "dataset": dataset, "train_seed": policy.config.seed, "step": policy.step,
               "train_seconds": policy.elapsed_seconds, "method": policy.config.agent, "nfe": None}
    result, _ = evaluate(GoalDecisions(policy.device), family, tasks, Execution().resolved(family, env), entries,
                         progress=progress,
                         follower=lambda n: PolicyFollower(n, family.body(env), policy.act, ahead=1))
    result.config = {**dataclasses.asdict(policy.config), "dataset": dataset}
    return result
