"""Policies moved between physics: each run's policy scored on the physics it trained on
and on the others, over the same episodes.

    python -m benchmarks.physics_transfer runs/hs-mjx runs/hs-native --physics native mjx \
        --episodes 128 --out benchmarks/physics_transfer/handshake_touching.json

Every run keeps its own scene settings (force margin, contact caps ...) and is evaluated
against the static partner (``env.scoring_env``, as robustness sweeps score)
with the deterministic policy of its latest checkpoint (``--best``: its best evaluation)
on ``--episodes`` fresh episodes of the evaluation seed, once per physics in
``--physics`` (``mjx_caps48``: MJX with its contact caps raised to 48 geom pairs / 64
contacts, the cap a gripping policy needs). Reported per run and physics: success at the
end (the headline) and at some step, the mean return, and the ratio of success at the end
to the run's own physics' (the transfer target: >= 0.9).
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
from pathlib import Path

from benchmarks import machine
from mjx_hands import env as env_lib
from mjx_hands.policies import load_policy
from mjx_hands.rollouts import EVAL_SEED, episode_keys, rollout, summarize

PHYSICS_SETTINGS = {
    "native": ("native", {}),
    "mjx": ("mjx", {}),
    "mjx_caps48": ("mjx", {"max_geom_pairs": 48, "max_contact_points": 64}),
    "warp": ("warp", {}),
}
"""``--physics`` names: (implementation, ``SceneConfig`` fields over the run's own)."""


def scored_env(config: env_lib.EnvConfig, name: str) -> env_lib.HandInteractionEnv:
    """The run's scoring environment on physics ``name`` (``PHYSICS_SETTINGS``)."""
    impl, scene_fields = PHYSICS_SETTINGS[name]
    scene = dataclasses.replace(config.scene, **scene_fields)
    return env_lib.scoring_env(dataclasses.replace(config, physics=impl, scene=scene))


def own_physics(config: env_lib.EnvConfig, backend: str, names: list[str]) -> str | None:
    """The ``--physics`` name that is the run's own physics (its implementation as it
    resolved, its scene's caps), or None when ``names`` lacks it."""
    for name in names:
        impl, scene_fields = PHYSICS_SETTINGS[name]
        same_scene = all(getattr(config.scene, k) == v for k, v in scene_fields.items())
        if impl == backend and same_scene:
            return name
    return None


def transfer(run_dir: Path, names: list[str], episodes: int, seed: int, best: bool) -> dict:
    """{'trained_on', 'epoch', 'scene', 'physics': {name: metrics and 'ratio_final'}}."""
    loaded = load_policy(run_dir, None, episodes, best)
    config = loaded.config.env
    trained_on = loaded.single.backend  # 'auto' resolved as the run's env resolved it here
    keys = episode_keys(seed, episodes)
    scored = {}
    for name in names:
        env = scored_env(config, name)
        metrics, _ = summarize(env, rollout(env, loaded.act, keys))
        scored[name] = {k: float(v) for k, v in metrics.items()}
        print(f"{run_dir} ({trained_on}-trained) on {name}: success at the end "
              f"{scored[name]['eval/success_final']:.3f}", flush=True)
    own = own_physics(config, trained_on, names)
    if own is None:
        print(f"note: {run_dir}'s own physics ({trained_on}) is not among {names}: no ratios")
    else:
        reference = scored[own]["eval/success_final"]
        for metrics in scored.values():
            metrics["ratio_final"] = metrics["eval/success_final"] / reference if reference else None
    return {
        "trained_on": trained_on,
        "physics_option": config.physics,
        "own": own,
        "epoch": loaded.epoch,
        "checkpoint": "best" if best else "latest",
        "scene": dataclasses.asdict(config.scene),
        "physics": scored,
    }


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", nargs="+", type=Path, help="train.py run folders")
    parser.add_argument("--physics", nargs="+", default=["native", "mjx"], choices=list(PHYSICS_SETTINGS))
    parser.add_argument("--episodes", type=int, default=128)
    parser.add_argument("--seed", type=int, default=EVAL_SEED)
    parser.add_argument("--best", action="store_true", help="each run's best-evaluated policy")
    parser.add_argument("--out", type=Path, help="JSON record")
    args = parser.parse_args(argv)
    missing = [str(r) for r in args.runs if not (r / "config.json").is_file()]
    if missing:
        parser.error(f"not train.py run folders (no config.json): {', '.join(missing)}")
    if "warp" in args.physics and importlib.util.find_spec("warp") is None:
        parser.error('--physics warp needs warp-lang: pip install -e ".[warp]"')
    record = machine.provenance("benchmarks.physics_transfer", argv) | {
        "episodes": args.episodes,
        "seed": args.seed,
        "runs": {},
    }
    for run_dir in args.runs:  # the record is written after each run: a late failure keeps them
        record["runs"][str(run_dir)] = transfer(run_dir, args.physics, args.episodes, args.seed, args.best)
        machine.write_record(args.out, record)
    return record


if __name__ == "__main__":
    main()
