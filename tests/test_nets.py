"""The temporal U-Net and the learned-prior MLP: sizes against closed forms, shapes, errors (tiny inputs)."""

from __future__ import annotations

import pytest
import torch

from bridgeplan.errors import BridgeplanError
from bridgeplan.nets.prior_mlp import PriorMLP
from bridgeplan.nets.unet import FrozenUNet, TemporalUNet, UNetConfig
from bridgeplan.trajectory import MAZE2D

OBS_DIM, TRANSITION_DIM = MAZE2D.obs_dim, MAZE2D.transition_dim


def n_params(module: torch.nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())


def diffuser_unet_params(transition_dim: int, dim: int, mults: tuple[int, ...]) -> int:
    """Parameter count of Diffuser's temporal U-Net, layer by layer from its description."""
    def conv(c_in, c_out, k):
        return c_in * c_out * k + c_out

    def block(c_in, c_out):  # Conv1d(5) -> GroupNorm -> Mish
        return conv(c_in, c_out, 5) + 2 * c_out

    def res(c_in, c_out):  # two blocks, the time projection Linear(dim, c_out), a 1x1 skip if needed
        return block(c_in, c_out) + block(c_out, c_out) + dim * c_out + c_out + (
            conv(c_in, c_out, 1) if c_in != c_out else 0)

    dims = [transition_dim, *(dim * m for m in mults)]
    pairs = list(zip(dims[:-1], dims[1:]))
    total = dim * 4 * dim + 4 * dim + 4 * dim * dim + dim  # time MLP dim -> 4 dim -> dim
    for k, (c_in, c_out) in enumerate(pairs):
        total += res(c_in, c_out) + res(c_out, c_out) + (conv(c_out, c_out, 3) if k < len(pairs) - 1 else 0)
    total += 2 * res(dims[-1], dims[-1])
    for c_in, c_out in reversed(pairs[1:]):
        total += res(2 * c_out, c_in) + res(c_in, c_in) + conv(c_in, c_in, 4)  # ConvTranspose1d(4)
    return total + block(dim, dim) + conv(dim, transition_dim, 1)


def test_diffuser_maze2d_unet_size():
    net = TemporalUNet(TRANSITION_DIM, dim=32, dim_mults=(1, 4, 8))
    count = n_params(net)
    assert count == diffuser_unet_params(TRANSITION_DIM, 32, (1, 4, 8)) == 3_682_118
    assert abs(count - 3.7e6) / 3.7e6 < 0.02  # Diffuser's "about 3.7 M" for Maze2D
    assert n_params(TemporalUNet(TRANSITION_DIM, dim=16, dim_mults=(1, 2, 4))) == diffuser_unet_params(
        TRANSITION_DIM, 16, (1, 2, 4))


@pytest.mark.parametrize("dim, mults, horizon", [(8, (1, 2), 6), (16, (1, 2, 4), 16), (8, (1,), 5)])
def test_unet_shape_and_time_dependence(dim, mults, horizon):
    torch.manual_seed(0)
    net = TemporalUNet(TRANSITION_DIM, dim=dim, dim_mults=mults, horizon=horizon)
    x = torch.randn(3, horizon, TRANSITION_DIM)
    out = net(x, torch.tensor([0.0, 3.0, 7.0]))
    assert out.shape == x.shape
    # integer step indices work too, and the time input changes the output
    assert torch.allclose(net(x, torch.tensor([0, 3, 7])), out)
    assert not torch.allclose(net(x, torch.tensor([1.0, 4.0, 8.0])), out)


def test_unet_config_and_horizon_errors():
    config = UNetConfig(32, (1, 4, 8))
    assert config.downsample_factor == 4 and UNetConfig(8, (1,)).downsample_factor == 1
    assert UNetConfig(8, [1, 2]).dim_mults == (1, 2)
    with pytest.raises(BridgeplanError, match="divisible by the U-Net.s downsampling factor 4"):
        TemporalUNet(TRANSITION_DIM, dim=8, dim_mults=(1, 2, 4), horizon=10)
    net = TemporalUNet.from_config(UNetConfig(8, (1, 2, 4)), TRANSITION_DIM, horizon=8)
    assert net.config == UNetConfig(8, (1, 2, 4))
    with pytest.raises(BridgeplanError, match="horizon 6"):
        net(torch.zeros(1, 6, TRANSITION_DIM), torch.zeros(1))
    with pytest.raises(BridgeplanError, match="multiple of 8"):
        UNetConfig(12, (1, 2))
    with pytest.raises(BridgeplanError, match="multipliers"):
        UNetConfig(8, ())


def test_prior_mlp_shape_and_size():
    horizon = 8
    net = PriorMLP(OBS_DIM, horizon, TRANSITION_DIM)
    width = horizon * TRANSITION_DIM
    assert n_params(net) == (2 * OBS_DIM * width + width) + (width * width + width)
    out = net(torch.randn(5, OBS_DIM), torch.randn(5, OBS_DIM))
    assert out.shape == (5, horizon, TRANSITION_DIM)
    assert isinstance(net.net[1], torch.nn.LeakyReLU) and net.net[1].negative_slope == 0.1


def test_mish_equals_torchs_mish_and_its_gradient():
    from bridgeplan.nets.unet import Mish

    # both tails (the clamp at 20, e^x underflowing) and the middle
    x = torch.cat([torch.linspace(-60, 60, 2001), torch.tensor([-1e4, -88.0, 19.99, 20.0, 20.01, 1e4])])
    x64 = x.double().requires_grad_()
    torch.nn.functional.mish(x64).sum().backward()
    mine = x.clone().requires_grad_()
    y = Mish()(mine)
    y.sum().backward()
    torch.testing.assert_close(y.double(), torch.nn.functional.mish(x.double()), rtol=2e-6, atol=1e-6)
    torch.testing.assert_close(mine.grad.double(), x64.grad, rtol=2e-6, atol=1e-6)
    # the backward is the derivative of the forward: float64 finite differences
    assert torch.autograd.gradcheck(Mish(), (torch.linspace(-8, 8, 41, dtype=torch.float64).requires_grad_(),))


def test_planning_gets_the_networks_very_numbers():
    # inference mode (planning) takes Mish's path without the autograd function: the same numbers, bit for bit
    from bridgeplan.config import preset_config
    from bridgeplan.runs import build_model

    config = preset_config("umaze", "cpu-small")
    torch.manual_seed(0)
    model = build_model(config).eval()
    x, t = torch.randn(3, config.horizon, config.layout.transition_dim), torch.tensor([0.1, 0.5, 0.9])
    with torch.no_grad():
        trained_path = model(x, t)
    with torch.inference_mode():
        planning_path = model(x, t)
    assert torch.equal(trained_path, planning_path)


@pytest.mark.parametrize("interval", [False, True])
def test_the_frozen_network_plans_with_the_networks_very_numbers(interval):
    """Traced once at batch 1, the frozen network gives the eager network's numbers bit for bit at any batch size
    (one and two time inputs); with gradients, or at another horizon, it is the eager network itself."""
    torch.manual_seed(0)
    net = TemporalUNet(6, 8, (1, 2, 4), horizon=32, interval=interval).eval()
    frozen = FrozenUNet(net, 32)
    calls = []
    net.register_forward_hook(lambda *_: calls.append(1))  # the eager network's calls (the graph has no hooks)
    for batch in (1, 3, 17):
        x, t, r = torch.randn(batch, 32, 6), torch.rand(batch) * 16, torch.rand(batch)
        args = (x, t, r) if interval else (x, t)
        with torch.inference_mode():
            eager = net(*args)
            calls.clear()
            assert torch.equal(frozen(*args), eager) and not calls
    x, t = torch.randn(2, 32, 6, requires_grad=True), torch.rand(2)
    args = (x, t, torch.rand(2)) if interval else (x, t)
    frozen(*args).sum().backward()  # training and CDDB's corrections differentiate through the eager network
    assert x.grad is not None and calls == [1]
    with torch.inference_mode():
        other = torch.randn(2, 64, 6)
        assert torch.equal(frozen(other, *args[1:]), net(other, *args[1:])) and calls == [1, 1, 1]
