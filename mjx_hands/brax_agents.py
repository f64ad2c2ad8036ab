"""Brax's own SAC and PPO trainers on the same task, for comparison with DDPG.

The hand environment speaks Brax's ``Env`` API, so Brax's trainers run it. Their
default wrappers would restart a finished episode from its cached *first* state
without new randomisation (and keep counting the env's own episode step), so the
trainers get :func:`wrap_for_brax` instead: the project's batched auto-reset, which
draws a fresh demonstration, target and start for every episode. Each trainer has its
own settings (:class:`SACConfig`, :class:`PPOConfig`: ``--sac.*``, ``--ppo.*``), which
``train.py``'s presets size like the DDPG preset beside them (:meth:`SACConfig.like`):
the same budget (``epochs × num_envs × env_steps_per_epoch``), 3×256 networks, DDPG's
replay sizes for SAC; ``eval_every`` sets how many evaluations Brax runs. After training the deterministic policy is evaluated
with the same success measure as DDPG (:func:`mjx_hands.rollouts.rollout`) and the
parameters are saved with ``brax.io.model`` as ``RUN_DIR/brax_params.pkl``;
:func:`load_policy` rebuilds the policy from them (``mjx_hands.evaluate`` and the other
evaluations load a SAC or PPO run through it).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import time
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from mjx_hands.rollouts import episode_keys, rollout, summarize

ALGOS = ("sac", "ppo")
"""The Brax trainers this module runs (``TrainConfig.algo``)."""
PARAMS_FILE = "brax_params.pkl"
"""The trained parameters in a run folder (``brax.io.model`` format)."""


@dataclasses.dataclass(frozen=True)
class SACConfig:
    """Brax's SAC as ``--algo sac`` trains it (``--sac.*``)."""

    hidden_sizes: tuple[int, ...] = (256, 256, 256)
    """Hidden layers of the policy and Q networks."""
    learning_rate: float = 1e-3
    discount: float | None = None
    """None: 1 - 1 / episode length (as DDPG's)."""
    batch_size: int = 256
    min_replay_size: int = 2_000
    max_replay_size: int = 1_000_000
    grad_updates_per_step: int = 4
    """SGD updates per environment step of the whole batch."""
    env_steps_per_epoch: int = 100
    """Steps of every environment per epoch: the budget is ``epochs × num_envs ×`` it."""

    @staticmethod
    def like(ddpg) -> SACConfig:
        """Sized like a ``DDPGConfig``: its networks, critic learning rate, discount, batch,
        replay sizes, updates per env step and steps per epoch (what SAC read before it had
        settings of its own, so a run's config.json without them reads back as it ran)."""
        return SACConfig(
            hidden_sizes=tuple(ddpg.hidden_sizes),
            learning_rate=ddpg.critic_learning_rate,
            discount=ddpg.discount,
            batch_size=ddpg.batch_size,
            min_replay_size=ddpg.min_replay_size,
            max_replay_size=ddpg.replay_capacity,
            grad_updates_per_step=max(1, ddpg.updates_per_iteration // max(ddpg.unroll_length, 1)),
            env_steps_per_epoch=ddpg.unroll_length * ddpg.iterations_per_epoch,
        )


@dataclasses.dataclass(frozen=True)
class PPOConfig:
    """Brax's PPO as ``--algo ppo`` trains it (``--ppo.*``)."""

    hidden_sizes: tuple[int, ...] = (256, 256, 256)
    """Hidden layers of the policy and value networks."""
    learning_rate: float = 3e-4
    discount: float | None = None
    """None: 1 - 1 / episode length (as DDPG's)."""
    unroll_length: int = 10
    batch_size: int | None = None
    """None: a quarter of ``num_envs``."""
    num_minibatches: int = 4
    num_updates_per_batch: int = 4
    entropy_cost: float = 1e-3
    env_steps_per_epoch: int = 100
    """Steps of every environment per epoch: the budget is ``epochs × num_envs ×`` it."""

    @staticmethod
    def like(ddpg) -> PPOConfig:
        """Sized like a ``DDPGConfig``: its networks, discount, unroll and steps per epoch."""
        return PPOConfig(
            hidden_sizes=tuple(ddpg.hidden_sizes),
            discount=ddpg.discount,
            unroll_length=ddpg.unroll_length,
            env_steps_per_epoch=ddpg.unroll_length * ddpg.iterations_per_epoch,
        )


def wrap_for_brax(env, episode_length: int, action_repeat: int = 1, randomization_fn=None):
    """Brax's ``wrap_env_fn``: vmap + the project's auto-reset (batched keys at reset).

    The env itself ends episodes at ``episode_length`` with ``truncation`` set, so no
    episode wrapper is added; ``action_repeat`` and ``randomization_fn`` are not
    supported (the env has its own control period and randomisation).
    """
    from mjx_hands.env import BatchedEnv

    if action_repeat != 1 or randomization_fn is not None:
        raise ValueError("the hand environments take no action_repeat or randomization_fn")
    if getattr(env, "episode_length", episode_length) != episode_length:
        raise ValueError(f"episode_length {episode_length} differs from the env's own")

    class BraxTrainingEnv(BatchedEnv):
        """Batched keys at ``reset`` and the episode bookkeeping Brax's trainers read
        (``steps``, ``episode_done``, ``episode_metrics``), with the env's own
        ``truncation`` (Brax's EpisodeWrapper would call the env's time limit a
        termination, since the env itself reports ``done`` there)."""

        def reset(self, rng: jax.Array):
            state = jax.vmap(self.env.reset)(rng)
            zeros = jnp.zeros_like(state.reward)
            state.info["terminal_obs"] = state.obs
            state.info["steps"] = zeros
            state.info["episode_done"] = zeros
            totals = {"sum_reward": zeros, "length": zeros}
            state.info["episode_metrics"] = totals | {k: zeros for k in state.metrics}
            return state

        def step(self, state, action: jax.Array):
            fresh = 1.0 - state.info["episode_done"]  # 0 where the last step ended an episode
            steps = state.info["steps"] * fresh + 1.0
            totals = {k: v * fresh for k, v in state.info["episode_metrics"].items()}
            state = super().step(state, action)
            totals["sum_reward"] = totals["sum_reward"] + state.reward
            totals["length"] = totals["length"] + 1.0
            for key, total in totals.items():
                if key in state.metrics and key not in ("sum_reward", "length", "reward"):
                    totals[key] = total + state.metrics[key]
            state.info.update(steps=steps, episode_done=state.done, episode_metrics=totals)
            return state

    return BraxTrainingEnv(env, num_envs=None)


def network_factory(algo: str, hidden_sizes: tuple[int, ...]):
    """Brax's network factory for ``algo``, with these hidden layers."""
    from brax.training.agents.ppo import networks as ppo_networks
    from brax.training.agents.sac import networks as sac_networks

    hidden = tuple(hidden_sizes)
    if algo == "ppo":
        return functools.partial(
            ppo_networks.make_ppo_networks,
            policy_hidden_layer_sizes=hidden,
            value_hidden_layer_sizes=hidden,
        )
    if algo == "sac":
        return functools.partial(sac_networks.make_sac_networks, hidden_layer_sizes=hidden)
    raise ValueError(f"unknown Brax algorithm {algo!r}; expected one of {ALGOS}")


def load_policy(run_dir, config, single):
    """(act, params) of a SAC or PPO run: the parameters it saved, in networks rebuilt as
    its trainer built them (observations normalised); ``act``: observations
    (..., observation_size) -> deterministic actions (..., action_size), the parameters
    bound as data (``jax.tree_util.Partial``)."""
    from pathlib import Path

    from brax.io import model as brax_model

    path = Path(run_dir) / PARAMS_FILE
    if not path.is_file():
        raise FileNotFoundError(
            f"{run_dir} holds no {config.algo} parameters ({PARAMS_FILE} missing): its "
            "training did not finish"
        )
    params = brax_model.load_params(str(path))
    apply = _rebuilt_apply(
        config.algo,
        tuple(getattr(config, config.algo).hidden_sizes),
        single.observation_size,
        single.action_size,
    )
    return jax.tree_util.Partial(apply, params), params


@functools.lru_cache(maxsize=8)
def _rebuilt_apply(algo: str, hidden_sizes: tuple[int, ...], observation_size, action_size):
    """apply(params, obs) -> deterministic action of the networks ``algo``'s trainer
    builds for these sizes; kept per shape, so loaded runs of one program share it."""
    from brax.training.acme import running_statistics
    from brax.training.agents.ppo import networks as ppo_networks
    from brax.training.agents.sac import networks as sac_networks

    # Brax's PPO trainer passes the observation's shape, SAC's its size.
    obs = (observation_size,) if algo == "ppo" else observation_size
    networks = network_factory(algo, hidden_sizes)(
        obs, action_size, preprocess_observations_fn=running_statistics.normalize
    )
    inference = {"ppo": ppo_networks, "sac": sac_networks}[algo].make_inference_fn
    return functools.partial(_deterministic_apply, inference(networks))


def _deterministic_apply(make_policy, params, obs):
    """The action of Brax's ``make_policy`` at ``params`` (the mode: no sampling, so no
    key used)."""
    return make_policy(params, deterministic=True)(obs, jax.random.PRNGKey(0))[0]


def run(config, services) -> dict[str, Any]:
    """Train Brax's SAC or PPO (``config.algo``) on the task; the run directory holds
    config.json, metrics.csv, success.png and the parameters (no checkpoint to resume).

    ``services``: the project loop's run folder, environments and logs
    (``learners.RunServices``; ``training.run_services`` makes them).
    """
    from brax.io import model as brax_model
    from brax.training.agents.ppo import train as ppo
    from brax.training.agents.sac import train as sac

    run_dir, out = services.run_dir, services.out
    if config.algo not in ALGOS:
        raise ValueError(f"brax_agents.run trains sac or ppo, not {config.algo!r}")
    if config.resume:
        raise ValueError(
            f"--resume continues DDPG runs only: --algo {config.algo} (Brax's trainer) "
            "keeps no checkpoint to continue from; start it in a new --run-dir"
        )
    if (run_dir / "config.json").exists() or (run_dir / "metrics.csv").exists():
        raise FileExistsError(
            f"{run_dir} already holds a run; choose another --run-dir for --algo {config.algo}"
        )
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "config.json").write_text(json.dumps(services.config_json, indent=2))
    _, _, single = services.make_envs(config, 1)
    episode_length = single.episode_length
    own = getattr(config, config.algo)  # SACConfig or PPOConfig
    num_timesteps = config.epochs * config.num_envs * own.env_steps_per_epoch
    num_evals = max(2, config.epochs // config.eval_every + 1)
    gamma = own.discount if own.discount is not None else 1.0 - 1.0 / episode_length
    log = services.metrics_log(run_dir)
    started = time.perf_counter()

    def progress(steps: int, metrics: dict[str, Any]) -> None:
        row = {"train/env_steps": float(steps), "time/wall_seconds": time.perf_counter() - started}
        row |= {k: float(np.asarray(v)) for k, v in metrics.items() if np.ndim(v) == 0}
        row["epoch"] = float(len(log.rows) + 1)
        log.append(row)
        reward = row.get("eval/episode_reward", float("nan"))
        print(
            f"{config.algo} {steps:>10,d} steps  eval return {reward:8.2f}  "
            f"{row['time/wall_seconds']:.0f} s",
            file=out,
            flush=True,
        )

    common = {
        "environment": single,
        "num_timesteps": num_timesteps,
        "episode_length": episode_length,
        "num_envs": config.num_envs,
        "num_eval_envs": config.eval_envs,
        "discounting": gamma,
        "seed": config.seed,
        "num_evals": num_evals,
        "normalize_observations": True,
        "progress_fn": progress,
        "wrap_env_fn": wrap_for_brax,
    }
    if config.algo == "ppo":
        make_policy, params, _ = ppo.train(
            **common,
            learning_rate=own.learning_rate,
            unroll_length=own.unroll_length,
            batch_size=own.batch_size or max(config.num_envs // 4, 1),
            num_minibatches=own.num_minibatches,
            num_updates_per_batch=own.num_updates_per_batch,
            entropy_cost=own.entropy_cost,
            network_factory=network_factory(config.algo, own.hidden_sizes),
        )
    elif config.algo == "sac":
        make_policy, params, _ = sac.train(
            **common,
            learning_rate=own.learning_rate,
            batch_size=own.batch_size,
            min_replay_size=own.min_replay_size,
            max_replay_size=own.max_replay_size,
            grad_updates_per_step=own.grad_updates_per_step,
            network_factory=network_factory(config.algo, own.hidden_sizes),
        )
    else:
        raise ValueError(f"unknown Brax algorithm {config.algo!r}; expected sac or ppo")
    brax_model.save_params(str(run_dir / PARAMS_FILE), params)

    # Brax's own inference function here; load_policy rebuilds it (tests compare the two).
    act = jax.tree_util.Partial(functools.partial(_deterministic_apply, make_policy), params)
    trajectory = rollout(single, act, episode_keys(config.seed + 1, config.eval_envs))
    final, _ = summarize(single, trajectory)  # the schema evaluate and DDPG report
    log.append({"epoch": float(len(log.rows) + 1), "train/env_steps": float(num_timesteps)} | final)
    log.close()
    services.plot_success(log.rows, run_dir / "success.png", f"{config.env.task} ({config.algo})")
    print(
        f"{config.algo}: success at the end {final['eval/success_final']:.2f} "
        f"(some step {final['eval/success']:.2f})",
        file=out,
        flush=True,
    )
    return {
        "run_dir": str(run_dir),
        "stop_reason": "epochs",
        "epochs": config.epochs,
        "last_checkpoint": None,
        "final_eval": final,
        "best_eval_success": final["eval/success"],
        "best_eval_success_final": final["eval/success_final"],
    }
