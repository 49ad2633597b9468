"""DATI's ensemble networks: shapes, constraints, the rank-one reward term, ablations (the
self-test's ablation flags remove their inputs)."""

from __future__ import annotations

from dataclasses import replace

import pytest
import torch

from aisdati.model.bc import BCConfig, BCPolicy
from aisdati.model.dati import DATIConfig, DATITrainer, gradient_penalty
from aisdati.model.env import TrajectoryImitationEnv
from aisdati.model.networks import DATINetworks, NetworkConfig, NonNegativeLinear, one_member
from aisdati.selftest.families import get_family
from aisdati.selftest.settings import SelftestSettings
from aisdati.selftest.sources import FamilySource

E, B = 3, 5
STATE, DECISION = 2, 3  # different on purpose, so that a swapped dimension fails


def _inputs(cfg: NetworkConfig, members: int = E, batch: int = B, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    x = torch.rand(members, batch, STATE, generator=g)
    a = torch.rand(members, batch, DECISION, generator=g) * 2 - 1
    eta = torch.randn(members, batch, cfg.latent_dim, generator=g) * 0.3
    t = torch.randint(0, 200, (members, batch, 1), generator=g).float()
    r = torch.where(torch.rand(members, batch, 1, generator=g) < 0.5, -1.0, 1.0)
    return x, a, eta, t, r


# ---------------------------------------------------------------------------- shapes
@pytest.mark.parametrize(
    "cfg",
    [NetworkConfig(), NetworkConfig(time_embedding=False), NetworkConfig(reward_input=False)],
    ids=["paper", "no-time", "no-reward"],
)
def test_output_shapes_and_ranges(cfg):
    nets = DATINetworks(STATE, DECISION, cfg, seeds=range(E))
    assert nets.members == E
    x, a, eta, t, r = _inputs(cfg)
    time = nets.time_features(t)
    assert [f.shape for f in time] == (
        [(E, B, 1), (E, B, cfg.time_embedding_dim - 1)] if cfg.time_embedding else []
    )
    fwd = nets.forward_actor(x, eta, time)
    bwd = nets.backward_actor(a, eta, time)
    assert fwd.shape == (E, B, DECISION) and bwd.shape == (E, B, STATE)
    for out in (fwd, bwd):
        assert torch.all(out >= -1) and torch.all(out <= 1)
    cf = nets.forward_critic(a, r, time)
    cb = nets.backward_critic(x, r, time)
    assert cf.shape == (E, B, 1) and cb.shape == (E, B, 1)
    assert torch.all(cf >= -1) and torch.all(cb >= -1)  # elu output
    assert torch.isfinite(cf).all() and torch.isfinite(cb).all()


def test_members_do_not_see_each_other():
    """Changing member 1's inputs leaves member 0's outputs untouched (and the reverse)."""
    cfg = NetworkConfig()
    nets = DATINetworks(STATE, DECISION, cfg, seeds=[1, 2])
    x, _, eta, t, _ = _inputs(cfg, members=2)
    out = nets.forward_actor(x, eta, nets.time_features(t))
    x2, eta2, t2 = x.clone(), eta.clone(), t.clone()
    x2[1], eta2[1], t2[1] = 0.123, -0.5, 42.0
    out2 = nets.forward_actor(x2, eta2, nets.time_features(t2))
    torch.testing.assert_close(out2[0], out[0], rtol=0, atol=0)
    assert not torch.allclose(out2[1], out[1])


def test_one_member_acts_as_that_member_of_the_ensemble_bit_for_bit():
    """A one-member copy (how a cross-fitted model's member scores and calibrates) gives
    member m's outputs of the whole ensemble exactly, for DATI's actor and BC's policy, and
    leaves the ensemble as it was."""
    cfg = NetworkConfig()
    nets = DATINetworks(STATE, DECISION, cfg, seeds=range(E))
    bc = BCPolicy(STATE, DECISION, BCConfig(), seeds=range(E))
    x, _, eta, t, _ = _inputs(cfg)
    whole = nets.forward_actor(x, eta, nets.time_features(t))
    whole_bc = bc(x, t)
    for m in range(E):
        single = one_member(nets, m)
        assert single.members == 1 and nets.members == E
        got = single.forward_actor(x[m : m + 1], eta[m : m + 1], single.time_features(t[m : m + 1]))
        torch.testing.assert_close(got[0], whole[m], rtol=0, atol=0)
        mean, log_std = one_member(bc, m)(x[m : m + 1], t[m : m + 1])
        torch.testing.assert_close(mean[0], whole_bc[0][m], rtol=0, atol=0)
        torch.testing.assert_close(log_std[0], whole_bc[1][m], rtol=0, atol=0)


# ---------------------------------------------------------------------------- non-negativity
@pytest.fixture(scope="module")
def trained_trainer():
    """A trainer after a few real steps, with a large critic learning rate so that the reward
    kernels are pushed hard."""
    torch.set_num_threads(1)
    fam = replace(get_family("circles"), steps=10)
    cfg = DATIConfig(episodes=1, batch_size=16, patience=0, lr_critic=1e-2)
    envs = [TrajectoryImitationEnv(FamilySource(fam)) for _ in range(2)]
    trainer = DATITrainer(envs, [3, 7], cfg)
    start = {
        name: p.detach().clone()
        for name, p in trainer.nets.named_parameters()
        if "reward_features.weight" in name
    }
    for _ in range(4):
        trainer.step()
    return trainer, start


def test_reward_kernel_stays_non_negative_after_optimiser_steps(trained_trainer):
    trainer, start = trained_trainer
    pushed_to_zero = 0
    for critic in ("forward_critic", "backward_critic"):
        w = getattr(trainer.nets, critic).reward_features.weight
        assert torch.all(w >= 0), critic
        assert not torch.equal(w, start[f"{critic}.reward_features.weight"])  # it was trained
        pushed_to_zero += int((w == 0).sum())
    assert pushed_to_zero > 0  # the projection did clip something back to 0


def test_non_negative_linear_starts_non_negative_and_projects():
    gens = [torch.Generator().manual_seed(s) for s in (0, 1)]
    layer = NonNegativeLinear(6, 4, gens)
    assert torch.all(layer.weight >= 0)
    with torch.no_grad():
        layer.weight[0, 0, 0] = -3.0
    layer.project_()
    assert layer.weight[0, 0, 0] == 0 and torch.all(layer.weight >= 0)


# ---------------------------------------------------------------------------- rank-one reward term
def test_tiled_then_equals_the_explicit_computation():
    members, batch, width, out = 2, 7, 92, 32
    gens = [torch.Generator().manual_seed(s) for s in (4, 5)]
    layer = NonNegativeLinear(width, width, gens)
    g = torch.Generator().manual_seed(9)
    with torch.no_grad():
        layer.bias.copy_(torch.randn(layer.bias.shape, generator=g))  # a trained, non-zero bias
    r = torch.where(torch.rand(members, batch, 1, generator=g) < 0.5, -1.0, 1.0)
    following = torch.randn(members, width, out, generator=g)
    tiled = r.expand(members, batch, width)
    explicit = torch.bmm(layer(tiled), following)
    torch.testing.assert_close(layer.tiled_then(r, following), explicit, rtol=1e-5, atol=1e-5)
    # and in float64, tightly
    layer64 = layer.double()
    explicit64 = torch.bmm(layer64(tiled.double()), following.double())
    torch.testing.assert_close(
        layer64.tiled_then(r.double(), following.double()), explicit64, rtol=1e-12, atol=1e-12
    )


def test_critic_uses_the_reward_only_when_asked():
    for reward_input in (True, False):
        cfg = NetworkConfig(reward_input=reward_input)
        nets = DATINetworks(STATE, DECISION, cfg, seeds=[0, 1, 2])
        _, a, _, t, r = _inputs(cfg)
        time = nets.time_features(t)
        plus = nets.forward_critic(a, torch.ones_like(r), time)
        minus = nets.forward_critic(a, -torch.ones_like(r), time)
        assert torch.equal(plus, minus) != reward_input


# ---------------------------------------------------------------------------- gradient penalty
def test_gradient_penalty_is_per_sample():
    cfg = NetworkConfig()
    nets = DATINetworks(STATE, DECISION, cfg, seeds=[3, 7])
    x, a, eta, t, r = _inputs(cfg, members=2, batch=6, seed=1)
    real = a
    fake = nets.forward_actor(x, eta, nets.time_features(t)).detach()
    u = torch.rand(2, 6, 1, generator=torch.Generator().manual_seed(2))
    time = nets.time_features(t)
    batch = gradient_penalty(nets.forward_critic, real, fake, r, time, u)
    assert batch.shape == (2,)
    singles = torch.stack(
        [
            gradient_penalty(
                nets.forward_critic,
                real[:, i : i + 1],
                fake[:, i : i + 1],
                r[:, i : i + 1],
                [f[:, i : i + 1] for f in time],
                u[:, i : i + 1],
            )
            for i in range(6)
        ]
    )
    torch.testing.assert_close(batch, singles.mean(dim=0), rtol=1e-5, atol=1e-6)

    # and each per-sample value is (‖∇x c(x̂)‖ − 1)² computed from scratch
    i = 4
    xh = u[:, i : i + 1] * real[:, i : i + 1] + (1 - u[:, i : i + 1]) * fake[:, i : i + 1]
    xh = xh.requires_grad_(True)
    c = nets.forward_critic(xh, r[:, i : i + 1], [f[:, i : i + 1] for f in time])
    (grad,) = torch.autograd.grad(c.sum(), xh)
    expected = (grad[:, 0].norm(dim=-1) - 1) ** 2
    torch.testing.assert_close(singles[i], expected, rtol=1e-5, atol=1e-6)


def test_gradient_penalty_is_differentiable_in_the_critic():
    cfg = NetworkConfig()
    nets = DATINetworks(STATE, DECISION, cfg, seeds=[3])
    x, _, _, t, r = _inputs(cfg, members=1, batch=4)
    gp = gradient_penalty(nets.backward_critic, x, x.flip(1), r, nets.time_features(t), t / 200)
    gp.sum().backward()
    grad = nets.backward_critic.input_features.weight.grad
    assert grad is not None and torch.any(grad != 0)


# ---------------------------------------------------------------------------- ablations
def _expected_parameters(cfg: NetworkConfig, state: int, decision: int, members: int) -> int:
    """Parameter count written out from the architecture (per member, times members)."""
    f, h, n = cfg.feature_units, cfg.hidden_units, cfg.hidden_layers
    time = cfg.time_embedding_dim if cfg.time_embedding else 0
    hidden_rest = (n - 1) * (h * h + h)

    def actor(i, o):
        return (
            (i * f + f)
            + (cfg.latent_dim * f + f)
            + ((2 * f + time) * h + h)
            + hidden_rest
            + (h * o + o)
        )

    def critic(i):
        other = f + time
        reward = other * other + other if cfg.reward_input else 0
        first_in = other + (other if cfg.reward_input else 0)
        return (i * f + f) + reward + (first_in * h + h) + hidden_rest + (h + 1)

    t2v = 2 * cfg.time_embedding_dim if cfg.time_embedding else 0
    per_member = actor(state, decision) + actor(decision, state) + critic(decision) + critic(state)
    return members * (per_member + t2v)


def _count(nets) -> int:
    return sum(p.numel() for p in nets.parameters())


@pytest.mark.parametrize("time_embedding", [True, False])
@pytest.mark.parametrize("reward_input", [True, False])
def test_parameter_counts(time_embedding, reward_input):
    cfg = NetworkConfig(time_embedding=time_embedding, reward_input=reward_input)
    nets = DATINetworks(STATE, DECISION, cfg, seeds=[0, 1])
    assert _count(nets) == _expected_parameters(cfg, STATE, DECISION, 2)


def _first_widths(module) -> list[int]:
    return [w.shape[1] for w in module.hidden.first.weights]


def test_time_embedding_ablation_removes_time2vec():
    full = DATINetworks(STATE, DECISION, NetworkConfig(), seeds=[0])
    ablated = DATINetworks(STATE, DECISION, NetworkConfig(time_embedding=False), seeds=[0])
    assert full.time2vec is not None and ablated.time2vec is None
    assert any("time2vec" in n for n, _ in full.named_parameters())
    assert not any("time2vec" in n for n, _ in ablated.named_parameters())
    assert ablated.time_features(torch.zeros(1, 2, 1)) == []
    for name in ("forward_actor", "backward_actor"):
        wide, narrow = _first_widths(getattr(full, name)), _first_widths(getattr(ablated, name))
        assert wide == [16, 16, 1, 75] and narrow == [16, 16]
        assert sum(wide) - sum(narrow) == 76
    for name in ("forward_critic", "backward_critic"):
        wide, narrow = _first_widths(getattr(full, name)), _first_widths(getattr(ablated, name))
        # features [16, 1, 75] then the reward block, as wide as them
        assert wide == [16, 1, 75, 92] and narrow == [16, 16]
        assert sum(wide[:-1]) - sum(narrow[:-1]) == 76
        assert getattr(ablated, name).reward_features.weight.shape == (1, 16, 16)
    assert _count(full) > _count(ablated)
    # the policy (what a rollout needs) carries the Time2Vec along with the forward actor
    policy = {id(p) for p in full.policy_parameters()}
    assert {id(full.time2vec.freq), id(full.time2vec.phase)} <= policy


def test_reward_ablation_removes_reward_features():
    full = DATINetworks(STATE, DECISION, NetworkConfig(), seeds=[0])
    ablated = DATINetworks(STATE, DECISION, NetworkConfig(reward_input=False), seeds=[0])
    for name in ("forward_critic", "backward_critic"):
        assert getattr(full, name).reward_features is not None
        assert getattr(ablated, name).reward_features is None
        assert _first_widths(getattr(ablated, name)) == [16, 1, 75]
    assert not any("reward_features" in n for n, _ in ablated.named_parameters())
    ablated.project_()  # nothing to project: must not fail
    other = 16 + 76
    per_critic = other * other + other + other * 32  # kernel, bias, first-layer reward block
    assert _count(full) - _count(ablated) == 2 * per_critic
    # actors are unaffected by the reward ablation
    for name in ("forward_actor", "backward_actor"):
        a = sum(p.numel() for p in getattr(full, name).parameters())
        b = sum(p.numel() for p in getattr(ablated, name).parameters())
        assert a == b


# ---------------------------------------------------------------------------- initialisation
@pytest.mark.parametrize("cfg", [NetworkConfig(), NetworkConfig(time_embedding=False)])
def test_member_initialisation_does_not_depend_on_the_ensemble(cfg):
    pair = DATINetworks(STATE, DECISION, cfg, seeds=[3, 7])
    alone7 = DATINetworks(STATE, DECISION, cfg, seeds=[7])
    alone3 = DATINetworks(STATE, DECISION, cfg, seeds=[3])
    p7, p3 = dict(alone7.named_parameters()), dict(alone3.named_parameters())
    for name, p in pair.named_parameters():
        assert torch.equal(p[1], p7[name][0]), name
        assert torch.equal(p[0], p3[name][0]), name
    # different seeds do differ
    assert not torch.equal(pair.forward_actor.out.weight[0], pair.forward_actor.out.weight[1])


def test_biases_start_at_zero_and_glorot_bounds_hold():
    nets = DATINetworks(STATE, DECISION, NetworkConfig(), seeds=[0, 1])
    for name, p in nets.named_parameters():
        if name.endswith("bias") and "time2vec" not in name:
            assert torch.count_nonzero(p) == 0, name
    w = nets.forward_actor.out.weight  # [E, 32, decision]
    bound = (6.0 / (32 + DECISION)) ** 0.5
    assert w.abs().max() <= bound


def test_ablation_flags_remove_the_inputs():
    settings = SelftestSettings()
    full = DATINetworks(2, 2, settings.dati_config("dati").network, [0])
    no_time = DATINetworks(2, 2, settings.dati_config("dati-no-time-embedding").network, [0])
    no_reward = DATINetworks(2, 2, settings.dati_config("dati-no-reward-input").network, [0])

    def first_widths(net):
        return [w.shape[1] for w in net.hidden.first.weights]

    # full: actors see (input 16, noise 16, time 1 + 75); critics (input 16, time, reward 92)
    assert first_widths(full.forward_actor) == [16, 16, 1, 75]
    assert first_widths(full.forward_critic) == [16, 1, 75, 92]
    # no time embedding: no Time2Vec anywhere, the time blocks are gone from every network
    assert no_time.time2vec is None and no_time.time_features(torch.zeros(1, 1, 1)) == []
    assert first_widths(no_time.forward_actor) == [16, 16]
    assert first_widths(no_time.backward_critic) == [16, 16]
    # no reward input: critics lose the reward layer and block, actors are untouched
    assert no_reward.forward_critic.reward_features is None
    assert first_widths(no_reward.forward_critic) == [16, 1, 75]
    assert _count(no_reward.forward_actor) == _count(full.forward_actor)
    reward_params = 92 * 92 + 92 + 92 * 32  # tiled-reward layer and its first-layer block
    assert _count(full.forward_critic) - _count(no_reward.forward_critic) == reward_params
    assert _count(no_time) < _count(full)
