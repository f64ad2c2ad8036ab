"""Environment profiles: the authors' environment (``paper``) and the project's own
(``project``), two named values of one setting, defined here and nowhere else.

A profile fixes what the environment observes, how contact is sensed and rewarded,
where the target hand is drawn, the reward weights of every task and variant, and the
learner's budget. ``config.json`` records the profile of every run; a grid's members
share it.

============== ======================================== ========================================
item           ``project`` (today's choices)            ``paper`` (the authors' environment)
============== ======================================== ========================================
observation    joints, velocities x 0.1, proximity      joints, velocities x dt (0.04 s), the
               contacts, agent points, goal and         target hand's 21 link positions
               imitation offsets, target points, phase  (world), touch sensors: no goal, no
               (145)                                    time (134)
contact        a phalanx geom within 2 mm of the        a touch sensor reads force > 0 (box
               target                                   sites on the palmar side: the authors')
contact term   +K_c per required sensor touching        -W_f per required sensor apart and per
                                                        forbidden one touching (clap thumb)
weights        one knob set per task, variants switch   the authors' config per task *and*
               terms off                                variant (main, baseline 1, baseline 2)
imitation      K_pI, K_alphaI relative to the goal      absolute W_ipos, W_iang (the authors'
               terms' weights (0.5, 0.5)                handshake baseline 2: 1, 0.2)
critic target  unclipped                                clipped to [-T, 0] (rewards are <= 0)
target box     ±5 cm cube                               the authors' per-task boxes
learner        ddpg-ln, 64 envs, replay 25.6            the paper's DDPG, 50 envs x T/25 steps
                                                        + 40 updates of 256 per cycle (replay
                                                        51.2 / 68.3), 1e6 transitions, 50
                                                        epochs of 50 cycles (500 k / 375 k env
                                                        steps), evaluation every 5 epochs
============== ======================================== ========================================

Remaining differences from the authors' code are listed, each with whether it was
measured to matter, in ``benchmarks/results/paper_profile.md``.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Literal

from mjx_hands import reward_params, tasks

PROFILES = ("project", "paper")
Profile = Literal["project", "paper"]

PAPER_IMITATION = {"W_ipos": 1.0, "W_iang": 0.2}
"""Imitation weights the paper profile adds when imitation is asked of a config without
its own: the authors' only released imitation weights (their handshake baseline 2)."""

PAPER_CYCLE = {"num_envs": 50, "updates_per_iteration": 40, "iterations_per_epoch": 50}
"""The authors' epoch in the project's loop: 50 cycles, each collecting 2 episodes'
worth of steps (2 T = 50 envs x T/25 steps) and making 40 updates of 256 with one
target-network update, as their 50 cycles x 2 rollouts x T steps with 40 batches."""


@dataclasses.dataclass(frozen=True)
class EnvProfile:
    """What a profile fixes in the environment."""

    observation: Literal["project", "paper"]
    """``project``: the project's layout (``env`` module docstring); ``paper``: the
    authors' (joints, velocities, target links, touch)."""
    contact_rule: Literal["proximity", "touch"]
    """``proximity``: a phalanx's collision geom within ``contact_distance`` of the target;
    ``touch``: its touch sensor reads a force (the authors')."""


ENV_PROFILES = {
    "project": EnvProfile(observation="project", contact_rule="proximity"),
    "paper": EnvProfile(observation="paper", contact_rule="touch"),
}


def check(profile: str) -> str:
    """``profile``, or a clear error naming the known ones."""
    if profile not in PROFILES:
        raise ValueError(f"unknown profile {profile!r}; expected one of {', '.join(PROFILES)}")
    return profile


def env_profile(profile: str) -> EnvProfile:
    return ENV_PROFILES[check(profile)]


def target_box(profile: str, task: str, half: tuple[float, float, float]) -> tasks.TargetBox:
    """The box the target palm is drawn from: the project's ``±half`` cube, or the
    authors' per-task box."""
    if check(profile) == "paper":
        box = tasks.spec(task).authors_target_box
        if box is None:
            raise ValueError(f"the paper profile has no target box for task {task!r}")
        return box
    return tasks.TargetBox.cube(half)


def paper_weights(
    task: str,
    reward: str,
    imitation: bool,
    knobs: reward_params.RewardKnobs | None = None,
) -> reward_params.RewardWeights:
    """The authors' reward for ``task`` in variant ``reward`` (``full`` is their main
    config; baselines are their baseline configs as released, the handshake's baseline 2
    with its own imitation), with :data:`PAPER_IMITATION` added when ``imitation`` asks
    for it and the config has none. ``knobs`` that are set override every variant's."""
    spec = tasks.spec(task)
    configs = dict(spec.authors_weights)
    if not configs:
        raise ValueError(
            f"the paper profile needs the authors' reward configs, and the paper did not "
            f"study {task!r}; train it with --profile project"
        )
    if reward not in configs:
        raise ValueError(
            f"the paper profile knows rewards {', '.join(configs)} for {task}, not {reward!r}"
        )
    w = configs[reward]
    w_ipos, w_iang = w.W_ipos, w.W_iang
    if imitation and w_ipos == 0 and w_iang == 0:
        w_ipos, w_iang = PAPER_IMITATION["W_ipos"], PAPER_IMITATION["W_iang"]
    values = {
        "K_p": float(w.W_pos),
        "K_c": float(w.W_f),
        "K_alpha": float(w.W_ang),
        "K_a": 0.0,  # the authors' reward has no action term (their actor loss has one)
        "K_pI": float(w_ipos),
        "K_alphaI": float(w_iang),
    }
    given = dataclasses.asdict(knobs or reward_params.RewardKnobs())
    values |= {k: float(v) for k, v in given.items() if v is not None}
    return reward_params.RewardWeights(
        **values,
        position_points="palm" if reward == "baseline1" else "fingertips",
        contact=values["K_c"] > 0,
        imitation=values["K_pI"] > 0 or values["K_alphaI"] > 0,
        contact_form="penalty",
        forbidden_contacts=spec.authors_forbidden_contacts,
        imitation_weights="absolute",
    )


def reward_weights(
    profile: str,
    task: str,
    reward: str,
    imitation: bool,
    knobs: reward_params.RewardKnobs | None = None,
) -> reward_params.RewardWeights:
    """The reward weights of ``task``'s variant (``reward``, ``imitation``) under
    ``profile``; ``knobs`` set override the profile's."""
    if check(profile) == "paper":
        return paper_weights(task, reward, imitation, knobs)
    base = reward_params.task_weights(task, knobs)
    weights = reward_params.reward_form(reward, base)
    return weights if imitation else dataclasses.replace(weights, imitation=False)


def target_clip(profile: str, episode_length: int) -> tuple[float, float] | None:
    """The critic target's clip: the authors' [-T, 0] (their ``clip_return`` = 1/(1-γ) =
    T, positive returns clipped, as their rewards are <= 0), none in the project's."""
    return (-float(episode_length), 0.0) if check(profile) == "paper" else None


def paper_learner(task: str) -> dict[str, Any]:
    """``TrainConfig`` fields of the paper profile for ``task`` (besides ``ddpg``
    fields in ``"ddpg"``): the authors' DDPG and budget (module docstring)."""
    length = tasks.spec(task).episode_length
    unroll = 2 * length // PAPER_CYCLE["num_envs"]
    return {
        "algo": "ddpg",
        "num_envs": PAPER_CYCLE["num_envs"],
        "epochs": 50,
        "eval_every": 5,
        "ddpg": {
            "batch_size": 256,
            "replay_capacity": 1_000_000,
            "min_replay_size": PAPER_CYCLE["num_envs"] * unroll,  # after the first cycle
            "unroll_length": unroll,
            "updates_per_iteration": PAPER_CYCLE["updates_per_iteration"],
            "iterations_per_epoch": PAPER_CYCLE["iterations_per_epoch"],
            "target_clip": target_clip("paper", length),
        },
    }
