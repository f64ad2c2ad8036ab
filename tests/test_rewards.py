"""Reward terms against a loop transcription of the paper's equations."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_reward_params import make_demo

from mjx_hands import reward_params as rp
from mjx_hands import rewards
from mjx_hands import shadow_hand as sh
from mjx_hands.reward_params import RewardParams

L = 7


def random_params(rng, batch=()) -> RewardParams:
    """Arbitrary (not Alg.-1-consistent) params, so every weight matters."""
    u = lambda *shape: rng.uniform(-1, 1, batch + shape).astype(np.float32)
    pos = lambda *shape: rng.uniform(0.05, 2, batch + shape).astype(np.float32)
    return RewardParams(
        j_min=rng.integers(0, 6, batch).astype(np.int32),
        d_min=pos(),
        t_min_frame=rng.integers(0, 20, batch).astype(np.int32),
        t_min_step=rng.integers(0, L, batch).astype(np.int32),
        imitation_length=rng.integers(1, L + 1, batch).astype(np.int32),
        contact_begin_step=np.zeros(batch, np.int32),
        contact_end_step=np.full(batch, 5, np.int32),
        goal_offsets=0.1 * u(6, 3),
        goal_angles=u(20),
        ref_offsets=0.1 * u(L, 6, 3),
        ref_angles=u(L, 20),
        ref_palm_pos=u(L, 3),
        ref_palm_rot=np.broadcast_to(np.eye(3, dtype=np.float32), batch + (L, 3, 3)),
        ref_target_joints=u(L, 20),
        w_position=pos(6),
        w_angle=pos(20),
        w_contact=pos(15) * rng.choice([-1.0, 0.0, 1.0], size=batch + (15,)).astype(np.float32),
        contact_bias=-pos(),
        w_action=pos(24),
        w_imitation_position=pos(6),
        w_imitation_angle=pos(20),
        required_contacts=rng.uniform(size=batch + (15,)) < 0.3,
        success_groups=rng.uniform(size=batch + (rp.N_GROUPS, 15)) < 0.2,
    )


def random_rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def random_inputs(rng, batch=()):
    n = int(np.prod(batch))
    rots = np.array([[random_rotation(rng) for _ in range(6)] for _ in range(n)])
    return {
        "hand_points": rng.uniform(-0.3, 0.3, batch + (6, 3)).astype(np.float32),
        "target_points": rng.uniform(-0.3, 0.3, batch + (6, 3)).astype(np.float32),
        "target_frames": rots.reshape(batch + (6, 3, 3)).astype(np.float32),
        "hand_angles": rng.uniform(-1, 1, batch + (20,)).astype(np.float32),
        "contacts": (rng.uniform(size=batch + (15,)) < 0.5).astype(np.float32),
        "action": rng.uniform(-1, 1, batch + (24,)).astype(np.float32),
    }


# -------------------------------------------------------------- loop transcription


def reference(p, step, x):
    """The paper's reward for one sample, one term at a time, with explicit loops."""
    j = int(p["j_min"])
    R, o = x["target_frames"][j], x["target_points"][j]

    def place(offset):  # p_j + R_j Δp
        return [o[a] + sum(R[a][b] * offset[b] for b in range(3)) for a in range(3)]

    def dist(a, b):
        return math.sqrt(sum((a[k] - b[k]) ** 2 for k in range(3)))

    r_p = 0.0
    for i in range(6):
        r_p -= p["w_position"][i] * dist(place(p["goal_offsets"][i]), x["hand_points"][i])
    r_a = 0.0
    for i in range(20):
        r_a -= p["w_angle"][i] * abs(p["goal_angles"][i] - x["hand_angles"][i])
    r_c = float(p["contact_bias"])
    for i in range(15):
        r_c += p["w_contact"][i] * (1.0 if x["contacts"][i] > 0.5 else 0.0)
    r_u = 0.0
    for i in range(24):
        r_u -= p["w_action"][i] * x["action"][i] ** 2
    r_pi = r_ai = 0.0
    if 0 <= step < int(p["imitation_length"]):
        for i in range(6):
            r_pi -= p["w_imitation_position"][i] * dist(
                place(p["ref_offsets"][step][i]), x["hand_points"][i]
            )
        for i in range(20):
            r_ai -= p["w_imitation_angle"][i] * abs(p["ref_angles"][step][i] - x["hand_angles"][i])
    terms = {
        "position": r_p, "angle": r_a, "contact": r_c, "action": r_u,
        "imitation_position": r_pi, "imitation_angle": r_ai,
    }  # fmt: skip
    terms["total"] = r_p + r_a + r_c + r_u + r_pi + r_ai
    return terms


def as_dict(params, idx=()):
    return {k: np.asarray(getattr(params, k))[idx] for k in params.__dataclass_fields__}


def assert_matches(out, params, step, x, batch, params_batched=True):
    for idx in np.ndindex(*batch):
        p = as_dict(params, idx if params_batched else ())
        s = int(np.asarray(step)[idx]) if np.ndim(step) else int(step)
        ref = reference(p, s, {k: v[idx] for k, v in x.items()})
        for term, value in ref.items():
            np.testing.assert_allclose(np.asarray(out[term])[idx], value, rtol=2e-5, atol=2e-5)


# ------------------------------------------------------------------------------ tests


@pytest.mark.parametrize("step", [0, 3, 6, 9, -1])
def test_unbatched_matches_reference(step):
    rng = np.random.default_rng(step + 10)
    params, x = random_params(rng), random_inputs(rng)
    out = rewards.compute_rewards(params, step, **x)
    assert set(out) == set(rewards.TERMS) | {"total"}
    assert all(v.shape == () for v in out.values())
    assert_matches(out, params, step, x, ())


@pytest.mark.parametrize("batch", [(5,), (2, 3)])
def test_batched_matches_reference(batch):
    rng = np.random.default_rng(len(batch))
    params, x = random_params(rng, batch), random_inputs(rng, batch)
    step = rng.integers(0, L + 2, batch)
    out = rewards.compute_rewards(params, step, **x)
    assert all(v.shape == batch for v in out.values())
    assert_matches(out, params, step, x, batch)


def test_unbatched_params_broadcast_over_batched_inputs():
    rng = np.random.default_rng(7)
    params, x = random_params(rng), random_inputs(rng, (4,))
    step = np.array([0, 2, 5, 8])
    out = rewards.compute_rewards(params, step, **x)
    assert_matches(out, params, step, x, (4,), params_batched=False)


def test_individual_terms_match_reference():
    rng = np.random.default_rng(3)
    params, x = random_params(rng, (6,)), random_inputs(rng, (6,))
    goal = rewards.goal_positions(
        x["target_points"], x["target_frames"], params.j_min, params.goal_offsets
    )
    ref_off, ref_ang, active = rewards.reference_at(params, np.full(6, 2))
    terms = {
        "position": rewards.position_reward(goal, x["hand_points"], params.w_position),
        "angle": rewards.angle_reward(params.goal_angles, x["hand_angles"], params.w_angle),
        "contact": rewards.contact_reward(x["contacts"], params.w_contact, params.contact_bias),
        "action": rewards.action_reward(x["action"], params.w_action),
        "imitation_angle": rewards.imitation_angle_reward(
            ref_ang, x["hand_angles"], params.w_imitation_angle, active
        ),
    }
    for b in range(6):
        ref = reference(as_dict(params, b), 2, {k: v[b] for k, v in x.items()})
        for term, value in terms.items():
            assert float(value[b]) == pytest.approx(ref[term], rel=2e-5, abs=2e-5), term
        np.testing.assert_allclose(ref_off[b], params.ref_offsets[b, 2])
        assert bool(active[b]) == (2 < params.imitation_length[b])


def test_goal_positions_in_target_body_frame():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(6, 3))
    rots = np.stack([random_rotation(rng) for _ in range(6)])
    off = rng.normal(size=(6, 3))
    for j in range(6):
        got = rewards.goal_positions(pts, rots, j, off)
        for i in range(6):
            want = [pts[j][a] + sum(rots[j][a][b] * off[i][b] for b in range(3)) for a in range(3)]
            np.testing.assert_allclose(got[i], want, rtol=1e-5, atol=1e-6)


def test_imitation_masked_past_length():
    rng = np.random.default_rng(1)
    params = random_params(rng).replace(imitation_length=np.int32(3))
    x = random_inputs(rng)
    on = rewards.compute_rewards(params, 2, **x)
    off = rewards.compute_rewards(params, 3, **x)
    assert float(on["imitation_position"]) < 0 and float(on["imitation_angle"]) < 0
    assert float(off["imitation_position"]) == 0 and float(off["imitation_angle"]) == 0


def test_success_rule():
    groups = rp.success_group_mask("handshake")  # all five middle phalanges, each alone
    mask = groups.any(0)
    assert [sh.CONTACT_SENSORS[i] for i in np.flatnonzero(mask)] == [
        "th_middle", "ff_middle", "mf_middle", "rf_middle", "lf_middle"
    ]
    contacts = mask.astype(np.float32)
    assert bool(rewards.success(contacts, groups))
    assert bool(rewards.success(np.ones(15, np.float32), groups))  # extra contacts are fine
    for i in np.flatnonzero(mask):
        missing = contacts.copy()
        missing[i] = 0
        assert not bool(rewards.success(missing, groups))
    batch = np.stack([contacts, np.zeros(15, np.float32), np.ones(15, np.float32)])
    np.testing.assert_array_equal(rewards.success(batch, groups), [True, False, True])
    assert bool(rewards.success(np.zeros(15), np.zeros((rp.N_GROUPS, 15), bool)))  # none required


def test_clap_success_needs_one_phalanx_of_each_finger():
    """The authors' clap rule, written out by sensor names, against the group masks."""
    groups = rp.success_group_mask("handclap")
    index = {n: i for i, n in enumerate(sh.CONTACT_SENSORS)}
    contacts = (np.random.default_rng(3).uniform(size=(512, 15)) < 0.55).astype(np.float32)
    expected = np.all(
        [
            (contacts[:, index[f"{f}_distal"]] > 0) | (contacts[:, index[f"{f}_middle"]] > 0)
            for f in ("ff", "mf", "rf", "lf")
        ],
        axis=0,
    )
    np.testing.assert_array_equal(rewards.success(contacts, groups), expected)
    assert 0.05 < expected.mean() < 0.95  # both outcomes occur
    # The contact term rewards all eight of them; the thumb is in no group.
    assert set(np.flatnonzero(rp.required_contact_mask("handclap"))) == set(
        np.flatnonzero(groups.any(0))
    ) and not groups[:, index["th_distal"]].any()


def test_jit_and_vmap_agree():
    rng = np.random.default_rng(5)
    params, x = random_params(rng, (8,)), random_inputs(rng, (8,))
    step = rng.integers(0, L, (8,))
    eager = rewards.compute_rewards(params, step, **x)
    jitted = jax.jit(rewards.compute_rewards)(params, step, **x)
    vmapped = jax.jit(jax.vmap(lambda p, s, xs: rewards.compute_rewards(p, s, **xs)))(
        params, step, x
    )
    for term in eager:
        np.testing.assert_allclose(jitted[term], eager[term], rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(vmapped[term], eager[term], rtol=1e-6, atol=1e-6)
    ok = jax.jit(jax.vmap(rewards.success))(jnp.asarray(x["contacts"]), params.success_groups)
    assert ok.shape == (8,)


def test_variants_change_exactly_their_terms():
    demo = make_demo(seed=2)
    rng = np.random.default_rng(9)
    x = random_inputs(rng)
    x["contacts"][[3, 4, 6, 7, 9, 10]] = 1.0  # some required handshake sensors touch
    # The baselines' forms with imitation kept, so each changes only its own terms.
    weights = {
        "full": rp.variant("full"),
        "baseline1": rp.reward_form("baseline1"),
        "baseline2": rp.reward_form("baseline2"),
        "no_imitation": rp.variant("no_imitation"),
    }
    out = {
        name: rewards.compute_rewards(rp.algorithm1(demo, w), 1, **x) for name, w in weights.items()
    }
    changed = {
        "baseline1": {"position", "imitation_position"},
        "baseline2": {"contact"},
        "no_imitation": {"imitation_position", "imitation_angle"},
    }
    assert float(out["full"]["contact"]) > 0
    assert float(out["full"]["imitation_angle"]) < 0
    for name, terms in changed.items():
        for term in rewards.TERMS:
            same = np.isclose(out[name][term], out["full"][term], rtol=1e-6, atol=1e-7)
            assert same != (term in terms), (name, term)
        assert not np.isclose(out[name]["total"], out["full"]["total"])
    assert float(out["baseline2"]["contact"]) == 0
    assert float(out["no_imitation"]["imitation_position"]) == 0
