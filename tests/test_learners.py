"""A learner is one module plus a registry entry: a toy random-action learner, written
here and registered at run time, trains through train.py, resumes, is evaluated and
runs as a grid, with no edit anywhere else."""

from __future__ import annotations

import json
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import struct
from tiny import HAND_GROUP, hand_cli_args

from mjx_hands import checkpoint, evaluate, experiments, learners, train_cli
from mjx_hands.agents.population import (
    Population,
    first_device,
    member,
    per_member,
    stack_members,
)


@struct.dataclass
class RandomState:
    params: Any  # {"action": (devices, members, act)}: the deterministic policy's action
    env_state: Any
    rng: jax.Array  # (devices, members, 2)
    env_steps: jax.Array  # (devices, members)


class RandomLearner:
    """Uniformly random actions while training; its policy is one constant action, the
    mean of the actions taken so far. Everything but that comes from ``Population``."""

    STEPS = 4

    def __init__(self, setup: learners.LearnerSetup):
        self.population = Population(
            setup.train_env,
            episode_length=setup.single.episode_length,
            eval_env=setup.eval_env,
            members=setup.members,
            member_info=setup.member_info,
            devices=setup.devices,
        )
        self.members = setup.members
        self.num_devices = self.population.num_devices
        self.action_size = setup.train_env.action_size
        self.trace_count = 0
        self._init = self.population.pmap(self._init_device)
        self._epoch = self.population.pmap(self._epoch_device, donate_argnums=0)
        self._evaluate = self.population.evaluation(self.act)

    def act(self, params, obs):
        return jnp.broadcast_to(params["action"], obs.shape[:-1] + (self.action_size,))

    @property
    def state_shapes(self):
        return jax.eval_shape(self.init, jax.random.PRNGKey(0))

    def init(self, rng):
        return self._init(self.population.device_keys(rng))

    def _init_device(self, rng):
        env_state = self.population.reset(self.population.env, rng)
        params = {"action": jnp.zeros((self.members, self.action_size))}
        return RandomState(params, env_state, rng, jnp.zeros((self.members,), jnp.int32))

    def run_epoch(self, state):
        state, metrics = self._epoch(state)
        return state, per_member(metrics, self.members)

    def _epoch_device(self, state: RandomState):
        self.trace_count += 1
        env = self.population.env

        def step(carry, _):
            env_state, rng, total = carry
            keys = jax.vmap(jax.random.split)(rng)
            rng, k_act = keys[:, 0], keys[:, 1]
            shape = env_state.obs.shape[1:-1] + (self.action_size,)
            action = jax.vmap(lambda k: jax.random.uniform(k, shape, minval=-1, maxval=1))(k_act)
            env_state = self.population.step(env, env_state, action)
            return (env_state, rng, total + action.mean(axis=1)), env_state.reward.mean(axis=1)

        zeros = jnp.zeros((self.members, self.action_size))
        (env_state, rng, total), reward = jax.lax.scan(
            step, (state.env_state, state.rng, zeros), None, length=self.STEPS
        )
        n = state.env_state.obs.shape[1]
        env_steps = state.env_steps + self.STEPS * n
        mean = jax.lax.pmean(total / self.STEPS, "devices")
        ones = jnp.ones((self.members,))
        metrics = {  # learners.EPOCH_METRICS, and one of its own
            "train/env_steps": jax.lax.psum(env_steps, "devices"),
            "train/episodes": 0.0 * ones,  # none ends within these few steps
            "train/episode_return": jnp.nan * ones,
            "train/success": 0.0 * ones,
            "train/params_finite": ones,
            "train/reward": jax.lax.pmean(reward.mean(axis=0), "devices"),
        }
        new = RandomState({"action": 0.5 * state.params["action"] + 0.5 * mean}, env_state, rng,
                          env_steps)  # fmt: skip
        return new, metrics

    def evaluate(self, state, rng):
        return self._evaluate(state.params, rng)

    def checkpoint_tree(self, state, save_replay: bool, index: int = 0):
        one = member(state, index)
        return {
            "params": jax.tree.map(first_device, one.params),
            "env_state": one.env_state,
            "rng": one.rng,
            "env_steps": one.env_steps,
        }

    def policy_tree(self, state, index: int = 0):
        return {"params": jax.tree.map(first_device, member(state, index).params)}

    def from_checkpoint_trees(self, trees, fresh):
        n = self.num_devices
        members = [
            member(fresh, i).replace(
                params=jax.tree.map(lambda x: np.broadcast_to(x, (n,) + x.shape), tree["params"]),
                env_state=tree["env_state"],
                rng=tree["rng"],
                env_steps=tree["env_steps"],
            )
            for i, tree in enumerate(trees)
        ]
        return self.population.to_devices(stack_members(members))

    def load_policy(self, ckpt_dir, step: int, verified: bool = False):
        like = self.policy_tree(self.state_shapes)
        tree, meta = checkpoint.restore(ckpt_dir, like, step, partial=True, verified=verified)
        params = tree["params"]
        return jax.tree_util.Partial(self.act, params), params, int(meta["epoch"])


ENTRY = learners.LearnerEntry("random", "uniformly random actions (a test's toy)", build=RandomLearner)


@pytest.fixture(scope="module")
def registered():
    learners.register(ENTRY)
    yield ENTRY
    learners.REGISTRY.pop(ENTRY.name)


@HAND_GROUP
def test_a_registered_toy_learner_trains_resumes_evaluates_and_runs_a_grid(tmp_path, registered):
    run = tmp_path / "run"
    args = [*hand_cli_args(), "--algo", "random", "--eval-every", "1"]
    assert train_cli.main([*args, "--epochs", "2", "--run-dir", str(run)]) == 0
    config = json.loads((run / "config.json").read_text())
    assert config["algo"] == "random"
    rows = (run / "metrics.csv").read_text().splitlines()
    assert len(rows) == 3  # header + 2 epochs

    assert train_cli.main(["--run-dir", str(run), "--resume", "--epochs", "3"]) == 0
    rows = (run / "metrics.csv").read_text().splitlines()
    assert len(rows) == 4  # the third epoch continued the run
    steps = [float(r.split(",")[rows[0].split(",").index("train/env_steps")]) for r in rows[1:]]
    assert steps == sorted(steps) and steps[-1] == 3 * steps[0]

    assert evaluate.main([str(run), "--episodes", "16", "--video-episodes", "0"]) == 0
    assert json.loads((run / "eval.json").read_text())["episodes"] == 16

    grid = tmp_path / "grid"
    grid_args = ["run", *args, "--epochs", "1", "--seeds", "2", "--variants", "full", "no_imitation"]
    assert experiments.main([*grid_args, "--run-dir", str(grid)]) == 0
    record = json.loads((grid / "grid.json").read_text())
    assert len(record["members"]) == 4
    assert {json.loads((grid / m["run_dir"] / "config.json").read_text())["algo"]
            for m in record["members"]} == {"random"}  # fmt: skip


def test_unknown_and_misregistered_learners_are_named(capsys):
    with pytest.raises(ValueError, match="unknown learner 'nope'; expected one of ddpg"):
        learners.entry("nope")
    with pytest.raises(ValueError, match="exactly one of build and run"):
        learners.LearnerEntry("both", "x", build=RandomLearner, run=print)
    with pytest.raises(ValueError, match="already registered"):
        learners.register(learners.LearnerEntry("ddpg", "another", build=RandomLearner))
    assert train_cli.main(["--algo", "nope", "--run-dir", "/nonexistent/x"]) != 0
    assert "--algo 'nope' is not a registered learner; expected one of ddpg" in (
        capsys.readouterr().err
    )
