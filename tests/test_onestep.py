"""The one-step processes (mean flow, shortcut model) against closed forms, limiting cases and a toy problem
whose answer is known, and through the real CLI on the tiny dataset."""

from __future__ import annotations

import json
import math

import pytest
import torch

from bridgeplan import config as cfg
from bridgeplan.cli import main
from bridgeplan.errors import BridgeplanError
from bridgeplan.nets.unet import TemporalUNet
from bridgeplan.processes import Distill, MeanFlow, Shortcut, make_process, process_from_dict
from bridgeplan.processes.samplers import ddim
from bridgeplan.trajectory import MAZE2D
from tests.test_train import train_args

F64 = torch.float64
B, H, D = 6, 8, 6
ACT_DIM = MAZE2D.act_dim


def conditions_for(x0: torch.Tensor) -> dict[int, torch.Tensor]:
    return {0: x0[:, 0, ACT_DIM:], H - 1: x0[:, -1, ACT_DIM:]}


def pair(seed=0) -> tuple[torch.Tensor, torch.Tensor, dict]:
    """A window x0 in [-0.9, 0.9] and a Gaussian prior sample x1 with x0's start and goal inpainted."""
    gen = torch.Generator().manual_seed(seed)
    x0 = torch.rand((B, H, D), generator=gen, dtype=F64) * 1.8 - 0.9
    x1 = torch.randn((B, H, D), generator=gen, dtype=F64)
    cond = conditions_for(x0)
    x1[:, 0, ACT_DIM:], x1[:, -1, ACT_DIM:] = cond[0], cond[H - 1]
    return x0, x1, cond


def tiny_net(seed=0, dtype=F64) -> TemporalUNet:
    torch.manual_seed(seed)
    return TemporalUNet(D, 8, (1, 2), interval=True).to(dtype)


# --- the exact flow between two Gaussians -----------------------------------------------------------

class GaussianFlow:
    """The flow from the prior N(m1, s1^2) at t = 1 to the data N(m0, s0^2) at t = 0 on the straight path
    ``z_t = (1 - t) x0 + t x1`` with x0, x1 independent (elementwise): ``z_t ~ N(mu_t, sigma_t^2)`` and the flow
    map is the monotone affine map between those marginals, ``phi_{t -> r}(z) = mu_r + (sigma_r / sigma_t)(z -
    mu_t)``; the average velocity over [r, t] is ``(z - phi(z)) / (t - r)``, the instantaneous one its limit
    ``dmu/dt + (dsigma/dt / sigma_t)(z - mu_t)``."""

    def __init__(self, m0, s0, m1, s1):
        self.m0, self.s0, self.m1, self.s1 = m0, s0, m1, s1

    def mu(self, t):
        return (1 - t) * self.m0 + t * self.m1

    def sigma(self, t):
        return ((1 - t) ** 2 * self.s0 ** 2 + t ** 2 * self.s1 ** 2) ** 0.5

    def average(self, z, r, t):
        phi = self.mu(r) + self.sigma(r) / self.sigma(t) * (z - self.mu(t))
        return (z - phi) / (t - r)

    def instantaneous(self, z, t):
        dsigma = ((t * self.s1 ** 2 - (1 - t) * self.s0 ** 2) / self.sigma(t))
        return self.m1 - self.m0 + dsigma / self.sigma(t) * (z - self.mu(t))

    def network(self, process):
        """A network that outputs the exact average velocity, reading (r, t) back from its time inputs the way
        the process encodes them; at a zero-length interval the instantaneous velocity."""
        def model(z, time, interval):
            t = (time / process.steps)[:, None, None]
            length = (interval + (1 if isinstance(process, Shortcut) else 0)) / process.steps
            r = t - length[:, None, None]
            zero = (t - r).abs() < 1e-12
            return torch.where(zero, self.instantaneous(z, t), self.average(z, r, torch.where(zero, t + 1, t)))
        return model


def test_the_average_velocity_over_a_vanishing_interval_is_the_instantaneous_velocity():
    flow, z = GaussianFlow(0.3, 0.2, -0.5, 1.0), torch.linspace(-2, 2, 9, dtype=F64)
    for t in (0.2, 0.5, 0.9):
        gaps = [float((flow.average(z, t - length, t) - flow.instantaneous(z, t)).abs().max())
                for length in (1e-3, 1e-5)]
        assert gaps[1] < 1e-3 and gaps[1] < 0.02 * gaps[0], gaps  # first order in the length


@pytest.mark.parametrize("process, nfes", [(MeanFlow(steps=8), (1, 2, 3)), (Shortcut(steps=8), (1, 2, 4))])
def test_jumps_with_the_exact_average_velocity_carry_the_prior_onto_the_data(process, nfes):
    """Gaussian to Gaussian: from prior draws, the sample after 1, 2, ... equal jumps has the data's mean and
    variance (Monte Carlo, 5 standard errors)."""
    m0, s0, m1, s1, n = 0.3, 0.2, -0.4, 0.7, 200_000
    flow = GaussianFlow(m0, s0, m1, s1)
    x1 = m1 + s1 * torch.randn((n, 1, 1), generator=torch.Generator().manual_seed(1), dtype=F64)
    for nfe in nfes:
        out = process.sample(flow.network(process), x1, {}, nfe)
        assert abs(float(out.mean()) - m0) < 5 * s0 / n ** 0.5, nfe
        assert abs(float(out.var()) - s0 ** 2) < 5 * s0 ** 2 * (2 / n) ** 0.5, nfe
    # the prior itself is far from it: a sampler that returned its start would fail above
    assert abs(float(x1.mean()) - m0) > 0.5


def test_the_mean_flow_target_over_a_zero_length_interval_is_the_velocity():
    """With every interval of zero length the MeanFlow target is v = x1 - x0 and the loss flow matching's."""
    x0, x1, cond = pair()
    net, process = tiny_net(), MeanFlow(steps=8, interval_share=0.0, adaptive_p=0.0)
    u, target, error = process.training_terms(net, x0, x1, cond, torch.Generator().manual_seed(2))
    assert torch.equal(target, x1 - x0)
    assert torch.allclose(error, ((u - (x1 - x0)) ** 2).flatten(1).mean(1))


def test_the_mean_flow_target_is_exact_on_the_exact_average_velocity():
    """The MeanFlow identity u = v - (t - r) du/dt through the process's own JVP on the curved Gaussian flow: pairs
    (x0, x1) built so that at the drawn time t their velocity x1 - x0 is the marginal one at z_t; on the exact
    network the target then equals the network's output, though v does not."""
    flow = GaussianFlow(0.25, 0.3, -0.3, 0.8)
    process = MeanFlow(steps=8, interval_share=1.0)
    _, t = process.draw_times(64, torch.Generator().manual_seed(3), "cpu", F64)
    t = t[:, None, None]
    z = torch.randn((64, 4, 3), generator=torch.Generator().manual_seed(4), dtype=F64)
    v = flow.instantaneous(z, t)
    x0, x1 = z - t * v, z + (1 - t) * v
    u, target, error = process.training_terms(flow.network(process), x0, x1, {}, torch.Generator().manual_seed(3))
    assert float((target - v).abs().max()) > 0.1  # the JVP term is not negligible here
    assert torch.allclose(target, u, atol=1e-9) and float(error.max()) < 1e-18


def test_the_mean_flow_jvp_is_the_total_derivative_along_the_flow():
    """The target's du/dt on a real network against a central difference along (z + h v, r, t + h)."""
    x0, x1, cond = pair(4)
    net, process = tiny_net(4), MeanFlow(steps=8, interval_share=1.0)
    gen = torch.Generator().manual_seed(5)
    u, target, _ = process.training_terms(net, x0, x1, cond, gen)
    r, t = process.draw_times(B, torch.Generator().manual_seed(5), "cpu", F64)
    z, v, h = process.path(x0, x1, t, cond), x1 - x0, 1e-6
    du = (process.average_velocity(net, z + h * v, r, t + h)
          - process.average_velocity(net, z - h * v, r, t - h)) / (2 * h)
    assert torch.allclose(target, (v - (t - r)[:, None, None] * du).detach(), atol=1e-6)


def test_shortcut_at_the_finest_step_is_flow_matching():
    """Without self-consistency rows the shortcut's loss is flow matching's on the velocity, at interval input 0."""
    x0, x1, cond = pair()
    net, process = tiny_net(), Shortcut(steps=8, bootstrap_share=0.0)
    z, r, t, target = process.training_targets(net, x0, x1, cond, torch.Generator().manual_seed(6))
    assert torch.equal(target, x1 - x0) and torch.allclose(process.interval_input(r, t), torch.zeros(B, dtype=F64))
    assert torch.allclose(z, process.path(x0, x1, t, cond))
    loss = process.training_loss(net, x0, x1, cond, torch.Generator().manual_seed(6))
    assert torch.allclose(loss, torch.mean((net(z, 8 * t, torch.zeros_like(t)) - (x1 - x0)) ** 2))


def test_shortcut_self_consistency_targets_are_exact_on_the_exact_average_velocity():
    """Two exact jumps of d are one exact jump of 2d: the bootstrap rows' targets are the exact average velocity
    over [t - 2d, t], at step sizes 2d that are powers of two and times on their grid."""
    flow = GaussianFlow(0.1, 0.3, -0.2, 0.9)
    gen = torch.Generator().manual_seed(7)
    x0 = 0.1 + 0.3 * torch.randn((400, 1, 1), generator=gen, dtype=F64)
    x1 = -0.2 + 0.9 * torch.randn((400, 1, 1), generator=gen, dtype=F64)
    process = Shortcut(steps=8, bootstrap_share=0.5)
    z, r, t, target = process.training_targets(flow.network(process), x0, x1, {}, gen)
    boot = slice(200, None)
    two_d = (t - r)[boot]
    assert set(torch.round(two_d * 8).tolist()) == {2.0, 4.0, 8.0}
    assert torch.allclose(torch.round(t[boot] / two_d) * two_d, t[boot]) and float(r.min()) > -1e-12
    want = flow.average(z[boot], r[boot][:, None, None], t[boot][:, None, None])
    assert torch.allclose(target[boot], want, atol=1e-10)


# --- training moves the sample from the prior to the data ----------------------------------------------

def fit(process, x0, x1, cond, steps=150, seed=0):
    """A tiny two-time network trained on the fixed pair (x0, x1) with Adam; returns it with the losses at the
    start and the end (each the mean of 8 fixed draws, so the two are comparable)."""
    net = tiny_net(seed, torch.float32)
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    gen = torch.Generator().manual_seed(seed)

    def measured() -> float:
        return sum(float(process.training_loss(net, x0, x1, cond, torch.Generator().manual_seed(100 + k)))
                   for k in range(8)) / 8

    before = measured()
    for _ in range(steps):
        opt.zero_grad()
        process.training_loss(net, x0, x1, cond, gen).backward()
        opt.step()
    return net, before, measured()


@pytest.mark.parametrize("process", [MeanFlow(steps=8), Shortcut(steps=8)], ids=["meanflow", "shortcut"])
def test_training_from_a_non_gaussian_prior_moves_the_one_step_sample_onto_the_data(process):
    """A deterministic, non-Gaussian prior (a ramp, as the line prior is a deterministic function of start and
    goal) and one data window: trained briefly, the loss falls and the one-step sample lands near the data and far
    from the prior sample it starts from (the lost attempt's mean flow returned the prior itself)."""
    pos = torch.linspace(-1, 1, H)
    data = torch.stack([torch.sin(3 * pos + k) * 0.8 for k in range(D)], -1)[None].repeat(4, 1, 1)
    ramp = torch.stack([pos * (k - 2.5) / 3 for k in range(D)], -1)[None].repeat(4, 1, 1)
    cond = conditions_for(data)
    prior = ramp.clone()
    prior[:, 0, ACT_DIM:], prior[:, -1, ACT_DIM:] = cond[0], cond[H - 1]
    net, before, after = fit(process, data, prior, cond)
    assert after < 0.2 * before, (before, after)
    with torch.no_grad():
        one_step = process.sample(net, prior, cond, 1)
    to_data, prior_to_data = (one_step - data).norm(), (prior - data).norm()
    assert to_data < 0.25 * prior_to_data, (float(to_data), float(prior_to_data))


# --- the processes as configs ---------------------------------------------------------------------------

@pytest.mark.parametrize("process", [MeanFlow(), MeanFlow(steps=4, interval_share=0.5, adaptive_p=0.0),
                                     Shortcut(), Shortcut(steps=32, bootstrap_share=0.5)])
def test_round_trip_through_dicts(process):
    d = json.loads(json.dumps(process.to_dict()))
    assert process_from_dict(d) == process
    assert make_process(d.pop("name"), **d) == process


def test_labels_and_run_tags():
    assert MeanFlow().label("line") == "mean flow (line)"
    assert MeanFlow(adaptive_p=0.0).run_tag("learned") == ["meanflow", "learned", "N16", "adaptive_p0.0"]
    assert Shortcut(steps=8).label("gaussian") == "shortcut (gaussian)"
    assert Shortcut().run_tag("line") == ["shortcut", "line", "N16"]
    assert MeanFlow.takes_interval and Shortcut.takes_interval and not MeanFlow.predicts_x0


@pytest.mark.parametrize("make, message", [
    (lambda: MeanFlow(steps=0), "mean flow steps must be >= 1"),
    (lambda: MeanFlow(interval_share=1.5), "interval_share must be in"),
    (lambda: MeanFlow(adaptive_p=float("nan")), "adaptive_p must be"),
    (lambda: MeanFlow(steps=4).validate_nfe(5), "nfe must be in 1..4"),
    (lambda: MeanFlow(steps=4).validate_nfe(0), "nfe must be in 1..4"),
    (lambda: Shortcut(steps=12), "power of two"),
    (lambda: Shortcut(bootstrap_share=-0.1), "bootstrap_share must be in"),
    (lambda: Shortcut(steps=8).validate_nfe(3), "nfe must be a power of two up to 8"),
    (lambda: Shortcut(steps=8).validate_nfe(16), "nfe must be a power of two up to 8"),
    (lambda: MeanFlow().with_sampler("euler"), "one way to sample"),
])
def test_bad_input(make, message):
    with pytest.raises(BridgeplanError, match=message) as e:
        make()
    assert "\n" not in str(e.value)


def test_mish_forward_mode_derivative_is_torchs():
    """The fast Mish's jvp (forward-mode AD, which the mean flow's target needs) against torch's own mish."""
    from torch.autograd import forward_ad

    from bridgeplan.nets.unet import Mish

    x = torch.linspace(-30, 30, 601, dtype=F64)
    tangent = torch.randn(x.shape, generator=torch.Generator().manual_seed(0), dtype=F64)
    with forward_ad.dual_level():
        ours = forward_ad.unpack_dual(Mish()(forward_ad.make_dual(x, tangent)))
        torchs = forward_ad.unpack_dual(torch.nn.functional.mish(forward_ad.make_dual(x, tangent)))
    assert torch.allclose(ours.primal, torchs.primal, atol=1e-12)
    assert torch.allclose(ours.tangent, torchs.tangent, atol=1e-12)


def test_a_network_without_an_interval_input_is_unchanged():
    """The second input is built only when asked for: the one-input network has the same parameters and initial
    weights as before it existed, and refuses an interval (as the two-input one refuses its absence)."""
    torch.manual_seed(0)
    plain = TemporalUNet(D, 8, (1, 2))
    torch.manual_seed(0)
    two = TemporalUNet(D, 8, (1, 2), interval=True)
    shared = plain.state_dict()
    assert all(torch.equal(shared[k], two.state_dict()[k]) for k in shared)
    assert set(two.state_dict()) - set(shared) and not any(k.startswith("interval") for k in shared)
    x, t = torch.randn(2, H, D), torch.rand(2)
    with pytest.raises(BridgeplanError, match="one time input"):
        plain(x, t, t)
    with pytest.raises(BridgeplanError, match="second time input"):
        two(x, t)


# --- through the CLI ---------------------------------------------------------------------------------

def one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:"), err
    return err[0]


CLI = {"meanflow": ["--process", "meanflow", "--prior", "line"],
       "shortcut": ["--process", "shortcut", "--prior", "line", "--diffusion-steps", "4"],
       "bridge": ["--process", "bridge", "--prior", "line", "--diffusion-steps", "6", "--process-param", "predict=ddbm",
                  "--process-param", "weighting=ddbm"]}  # DDBM's parametrization of the bridge


@pytest.mark.parametrize("name", list(CLI))
def test_train_and_eval_through_the_cli(tiny_dataset, tmp_path, capsys, name):
    run = tmp_path / "run"
    assert main(train_args(tiny_dataset, run, 3, *CLI[name])) == 0
    capsys.readouterr()
    saved = json.loads((run / "config.json").read_text())["config"]
    assert saved["process"]["name"] == name and saved["prior"] == "line"
    if name == "bridge":
        assert (saved["process"]["predict"], saved["process"]["weighting"]) == ("ddbm", "ddbm")
        assert run.name == "run" and "predictddbm-weightingddbm" in cfg.from_dict(cfg.TrainConfig, saved).run_name()
    for nfe in (1, 2):
        assert main(["eval", str(run), "--episodes", "4", "--device", "cpu", "--nfe", str(nfe), "--json"]) == 0
        result = json.loads(capsys.readouterr().out)
        assert result["process"] == name and result["nfe"] == nfe and result["prior"] == "line"
        assert math.isfinite(result["score"]["minari"]["mean"])
    impossible = {"shortcut": "3", "meanflow": "7", "bridge": "6"}[name]  # not a power of two; above the steps
    written = sorted(run.rglob("*"))
    assert main(["eval", str(run), "--episodes", "2", "--device", "cpu", "--nfe", impossible]) == 2
    assert "nfe must be" in one_error_line(capsys)
    assert sorted(run.rglob("*")) == written


# --- DDPM distilled -------------------------------------------------------------------------------------

def test_distill_targets_are_the_teacher_at_the_last_steps_and_the_student_one_ddim_step_down():
    """Rows with n < skip take the teacher's x0 prediction; the others the student's output at x_m, the teacher's
    DDIM step (eta 0) from n to m = n - skip, built here by the DDIM sampler itself."""
    process = Distill(steps=10, skip=3)
    gen = torch.Generator().manual_seed(8)
    x0 = torch.rand((64, H, D), generator=gen, dtype=F64) * 1.8 - 0.9

    def teacher(x, n):  # an arbitrary smooth x0 predictor
        return torch.tanh(0.7 * x + 0.05 * n[:, None, None])

    def student(x, n):
        return torch.sin(x - 0.1 * n[:, None, None])

    x_n, n, target = process.consistency_pair(student, teacher, x0, {}, gen)
    assert set(n.tolist()) == set(range(10))
    for row in range(64):
        k, x = int(n[row]), x_n[row:row + 1]
        if k < 3:
            assert torch.allclose(target[row], teacher(x, n[row:row + 1].to(F64))[0]), k
            continue
        seen = {}

        def predict(z, step):
            seen[step] = z
            return teacher(z, torch.full((1,), float(step), dtype=F64)).clamp(-1, 1) if step == k else z

        ddim(predict, x, {}, [k, k - 3], process.alpha_bar, eta=0.0)
        want = student(seen[k - 3], torch.full((1,), float(k - 3), dtype=F64)).clamp(-1, 1)
        assert torch.allclose(target[row], want[0], atol=1e-12), k


def test_a_student_equal_to_an_exact_teacher_of_a_point_mass_has_zero_loss():
    """Data a single trajectory c: the teacher that predicts c from anywhere is exact, its ODE ends at c from every
    (x_n, n), and the student equal to it is already the consistency function (zero loss); another is not."""
    c = torch.rand((1, H, D), generator=torch.Generator().manual_seed(9), dtype=F64) * 1.8 - 0.9
    x0 = c.repeat(32, 1, 1)

    def exact(x, n):
        return c.expand_as(x)

    process = Distill(steps=8, skip=2)
    assert float(process.training_loss(exact, x0, x0, {}, torch.Generator().manual_seed(1), teacher=exact)) == 0
    assert float(process.training_loss(lambda x, n: 0 * x, x0, x0, {}, torch.Generator().manual_seed(1),
                                       teacher=exact)) > 0.01
    with pytest.raises(BridgeplanError, match="teacher"):
        process.training_loss(exact, x0, x0, {})


def test_distill_samples_in_one_or_two_calls_at_steps_a_consistency_function_uses():
    assert Distill(steps=16).sample_steps(1) == [15] and Distill(steps=16).sample_steps(2) == [15, 8]
    assert Distill().max_nfe == 2 and Distill(teacher="/somewhere/run").variant() == {}
    assert Distill(skip=2).run_tag("gaussian") == ["distill", "N64", "skip2"]
    for nfe in (0, 3):
        with pytest.raises(BridgeplanError, match="nfe must be 1 or 2"):
            Distill().validate_nfe(nfe)
    with pytest.raises(BridgeplanError, match="skip must be in 1..7"):
        Distill(steps=8, skip=8)


def test_distill_training_lowers_its_loss():
    """A tiny teacher, its copy as the student, trained briefly on the consistency loss."""
    torch.manual_seed(3)
    teacher = TemporalUNet(D, 8, (1, 2)).requires_grad_(False)
    student = TemporalUNet(D, 8, (1, 2))
    student.load_state_dict(teacher.state_dict())
    x0, _, cond = pair(5)
    x0, cond = x0.float(), {k: v.float() for k, v in cond.items()}
    process = Distill(steps=8, skip=2)
    opt = torch.optim.Adam(student.parameters(), lr=3e-3)

    def measured() -> float:
        return sum(float(process.training_loss(student, x0, x0, cond, torch.Generator().manual_seed(50 + k),
                                               teacher=teacher).detach()) for k in range(8)) / 8

    before, gen = measured(), torch.Generator().manual_seed(0)
    for _ in range(80):
        opt.zero_grad()
        process.training_loss(student, x0, x0, cond, gen, teacher=teacher).backward()
        opt.step()
    assert measured() < 0.5 * before


@pytest.fixture(scope="module")
def distilled(tiny_runs, tiny_dataset, tmp_path_factory):
    run = tmp_path_factory.mktemp("distill") / "run"
    assert main(train_args(tiny_dataset, run, 3, "--process", "distill", "--process-param",
                           f"teacher={tiny_runs['ddpm']}")) == 0
    return run


def test_distill_through_the_cli(distilled, tiny_runs, capsys):
    capsys.readouterr()
    from bridgeplan.runs import load_planner

    planner, info = load_planner(distilled, device="cpu")
    assert info.config.process.name == "distill" and info.config.process.steps == 6
    assert info.portable_config["process"]["teacher"] == tiny_runs["ddpm"].name
    # the student started from the teacher's weights: after 3 steps at lr 1e-3 they are still close
    teacher, _ = load_planner(tiny_runs["ddpm"], device="cpu")
    gap = max(float((a - b).abs().max()) for a, b in zip(planner.model.state_dict().values(),
                                                        teacher.model.state_dict().values()))
    assert gap < 0.05
    for nfe in (1, 2):
        assert main(["eval", str(distilled), "--episodes", "4", "--device", "cpu", "--nfe", str(nfe), "--json"]) == 0
        result = json.loads(capsys.readouterr().out)
        assert result["process"] == "distill" and result["nfe"] == nfe and result["method"] == "DDPM distilled"
        assert result["process_params"]["teacher"] == tiny_runs["ddpm"].name  # no path of this machine
    written = sorted(distilled.rglob("*"))
    assert main(["eval", str(distilled), "--episodes", "2", "--device", "cpu", "--nfe", "3"]) == 2
    assert "nfe must be 1 or 2" in one_error_line(capsys)
    assert sorted(distilled.rglob("*")) == written


@pytest.mark.parametrize("teacher, extra, message", [
    ("bridge", [], "is a bridge run; distill distills a DDPM run"),
    ("ddpm", ["--horizon", "16"], "was trained for horizon 32, not 16"),
    ("ddpm", ["--diffusion-steps", "4"], "has 6 diffusion steps, the student 4"),
    ("ddpm", ["--dim", "16"], "was trained for model"),
    ("missing", [], "does not exist"),
    ("", [], "needs a teacher"),
])
def test_distill_refuses_a_teacher_it_cannot_distill(tiny_runs, tiny_dataset, tmp_path, capsys, teacher, extra,
                                                     message):
    run = tmp_path / "run"
    where = {"bridge": tiny_runs["bridge"], "ddpm": tiny_runs["ddpm"], "missing": tmp_path / "nothing", "": ""}
    assert main(train_args(tiny_dataset, run, 2, "--process", "distill", "--process-param",
                           f"teacher={where[teacher]}", *extra)) == 2
    assert message in one_error_line(capsys)
    assert not run.exists()


ONESTEP_STUDY = """
[[experiments]]
name = "onestep"
last_snapshot_only = true
series = [{ method = "ddpm", nfe = [1, 4] }, { method = "distill", nfe = [1, 2] },
          { method = "meanflow-line", nfe = [1, 2] }, { method = "shortcut-line", nfe = [1, 2] }]

[methods.ddpm]
process = "ddpm"

[methods.distill]
process = "distill"

[methods.meanflow-line]
process = "meanflow"
prior = "line"

[methods.shortcut-line]
process = "shortcut"
prior = "line"
"""


def test_a_study_trains_the_teacher_then_distills_it_and_scores_every_one_step_process(tiny_dataset, tmp_path):
    """A tiny study of the one-step processes against DDPM: the distilled student's teacher is the study's own DDPM
    run of the same seed (trained first), and the stored rows name it without a path of this machine."""
    from bridgeplan.experiments.store import ResultsStore
    from tests.test_experiments import TINY_STUDY

    (tmp_path / "studies").mkdir()
    text = TINY_STUDY.format(dataset=tiny_dataset, steps=2, seeds=[0]).replace("diffusion_steps = 6",
                                                                               "diffusion_steps = 4")
    (tmp_path / "studies" / "tiny.toml").write_text(text + ONESTEP_STUDY)
    assert main(["study", "run", "tiny", "--no-progress", "--root", str(tmp_path)]) == 0
    rows = ResultsStore(tmp_path / "results" / "tiny" / "results.sqlite").rows("onestep")
    assert sorted((r["process"], r["prior"], r["nfe"]) for r in rows) == [
        ("ddpm", "gaussian", 1), ("ddpm", "gaussian", 4), ("distill", "gaussian", 1), ("distill", "gaussian", 2),
        ("meanflow", "line", 1), ("meanflow", "line", 2), ("shortcut", "line", 1), ("shortcut", "line", 2)]
    teacher = next(json.loads(r["config"])["process"]["teacher"] for r in rows if r["process"] == "distill")
    ddpm_run = next(r["run_name"] for r in rows if r["process"] == "ddpm")
    assert teacher == ddpm_run and str(tmp_path) not in json.dumps(rows)
