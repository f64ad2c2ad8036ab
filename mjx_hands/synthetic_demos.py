"""The project's own demonstrations: minimum-jerk approaches to hand-designed contacts.

So that a fresh clone trains without the authors' recordings, this generates, for each
task with a synthetic design (``tasks.TaskSpec.synthetic``, written in the task's
module), ``NUM_DEMOS`` demonstrations in the :class:`mocap.Demonstration` schema and
writes them to ``mocap_data/<task>.npz``::

    python -m mjx_hands.synthetic_demos                   # regenerate mocap_data/
    python -m mjx_hands.synthetic_demos --task fist_bump  # one task
    python -m mjx_hands.synthetic_demos --out DIR         # elsewhere

Model (all in the target palm frame, see ``mocap``):

* Contact pose of the actor palm, designed from the Shadow model's geometry by the
  task's ``contact_pose`` (e.g. the handshake's palms a palm thickness apart with the
  thumb webs interlocked; the E.T. index pointing into the target's index pad).
* Approach: the palm moves on a straight minimum-jerk path (Flash & Hogan 1985) from a
  start 0.30-0.45 m away (backed off along the actor's forearm and along the task's
  ``retreat``, out of the target's way) while its orientation turns along the geodesic
  from a perturbed start.
* Fingers: minimum-jerk blend from a relaxed open hand to the task posture; a task with
  a ``squeeze`` (the handshake) closes further during contact.
* Target: a static per-task posture.
* Variability per demonstration (seeded by the task's ``seed_key`` or name): contact
  offsets of 1-2 cm and a few degrees, approach distance, duration and direction,
  closure amounts, hold time, target posture.

No number here comes from the recordings; ``tests/test_mocap.py`` checks the designed
contacts against the real data's mean contact pose.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from mjx_hands import hand_kinematics, mocap, tasks
from mjx_hands.demo_design import RELAXED, minimum_jerk, rodrigues

FPS = 120.0
"""Sampling rate of the synthetic demonstrations, Hz (the rate assumed for the release)."""
NUM_DEMOS = 8
SEED = 20190520  # ICRA 2019's opening day; any fixed value works.


def design(task: str) -> tasks.SyntheticDesign:
    """The registered synthetic design of ``task``; a clear error if it has none."""
    found = tasks.spec(task).synthetic
    if found is None:
        raise mocap.MocapError(
            f"task {task!r} has no synthetic design (its module's SyntheticDesign); "
            "import its recordings with `python -m mjx_hands.import_mocap` instead"
        )
    return found


def contact_pose(
    task: str, actor: np.ndarray, target: np.ndarray, tilt: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Designed actor palm pose at contact, in the target palm frame.

    Args:
      task: a registered task with a synthetic design.
      actor, target: (20,) postures at contact (used for the fingertip geometry).
      tilt: (3, 3) optional rotation applied in the actor palm frame before the position
        is solved, so that the defining contact (webs, index tips) still holds.
    Returns:
      position (3,) of the actor palm centre, rotation (3, 3) of the actor palm axes.
    """
    return design(task).contact_pose(actor, target, np.eye(3) if tilt is None else tilt)


def generate(
    task: str,
    index: int,
    rng: np.random.Generator,
    fps: float = FPS,
    plan: tasks.SyntheticDesign | None = None,
) -> mocap.Demonstration:
    """One synthetic demonstration of ``task`` (draws from ``rng``) by ``plan`` (default:
    the task's registered design)."""
    plan = plan or design(task)
    actor_goal = plan.actor_posture * rng.uniform(0.85, 1.1)
    target = hand_kinematics.clip_to_range(plan.target_posture + rng.normal(0.0, 0.03, 20))
    actor_goal = hand_kinematics.clip_to_range(actor_goal)
    tilt = rodrigues(rng.normal(0.0, np.radians(3.0), 3))
    pos_c, rot_c = plan.contact_pose(actor_goal, target, tilt)
    pos_c = pos_c + rng.normal(0.0, 1.0, 3) * np.asarray(plan.contact_jitter)

    approach_s = rng.uniform(1.1, 1.7)
    hold_s = rng.uniform(0.4, 0.9)
    begin = int(np.rint(approach_s * fps))
    num_frames = begin + int(np.rint(hold_s * fps)) + 1
    t = np.arange(num_frames)

    # Start: backed off along the actor's forearm and out of the target's way.
    retreat = np.asarray(plan.retreat) - rot_c[:, 2] + rng.normal(0.0, 0.1, 3)
    retreat /= np.linalg.norm(retreat)
    pos_0 = pos_c + rng.uniform(0.30, 0.45) * retreat
    turn = rng.normal(0.0, 1.0, 3)
    turn *= np.radians(rng.uniform(20.0, 40.0)) / np.linalg.norm(turn)

    s = minimum_jerk(t / begin)  # (T,)
    pos = pos_0 + s[:, None] * (pos_c - pos_0)
    rot = np.stack([rot_c @ rodrigues((1.0 - si) * turn) for si in s])

    # Fingers: close during the second part of the approach.
    close_from = rng.uniform(0.3, 0.6) * begin
    closure = minimum_jerk((t - close_from) / (begin - close_from))
    actor = RELAXED + closure[:, None] * (actor_goal - RELAXED)
    if plan.squeeze is not None:
        squeeze = minimum_jerk((t - begin) / (0.25 * fps)) * rng.uniform(0.7, 1.2)
        actor = actor + squeeze[:, None] * plan.squeeze
    return mocap.build_demonstration(
        task=task,
        name=f"{task}/synthetic/{index:02d}",
        source="synthetic",
        fps=fps,
        actor_joints=actor,
        target_joints=np.broadcast_to(target, (num_frames, 20)),
        actor_palm_pos=pos,
        actor_palm_rot=rot,
        contact_begin=begin,
        contact_end=num_frames - 1,
    )


def generate_task(
    task: str,
    num: int = NUM_DEMOS,
    seed: int = SEED,
    plan: tasks.SyntheticDesign | None = None,
) -> list[mocap.Demonstration]:
    """``num`` demonstrations of ``task`` by ``plan`` (default: its registered design);
    deterministic for a given seed."""
    plan = plan or design(task)
    key = tasks.name_key(task) if plan.seed_key is None else plan.seed_key
    rng = np.random.default_rng([seed, key])
    return [generate(task, i, rng, plan=plan) for i in range(num)]


def designed_tasks() -> tuple[str, ...]:
    """The registered tasks that have a synthetic design."""
    return tuple(t for t in tasks.TASKS if tasks.spec(t).synthetic is not None)


def write_task(
    task: str, out: Path = mocap.SYNTHETIC_PATH, num: int = NUM_DEMOS, seed: int = SEED
) -> Path:
    """Generate ``task`` and write ``out/<task>.npz``; a task whose design asks for takes
    (``TaskSpec.synthetic_takes``) is written as takes into ``out/<task>/`` first and
    imported from there (with the import's report beside the npz)."""
    from mjx_hands.mocap import mapping as mapping_lib
    from mjx_hands.mocap import takes

    demos = generate_task(task, num, seed)
    file = out / f"{task}.npz"
    fmt = tasks.spec(task).synthetic_takes
    if fmt is not None:
        folder = out / task
        mapping = mapping_lib.load_mapping(takes.export_demos(demos, folder, fmt))
        paths = takes.take_paths(folder, fmt)
        demos = takes.import_takes(paths, mapping, task)
        takes.write_import_report(demos, mapping, paths, file)
    mocap.save_npz(demos, file)
    return file


def write_all(
    out: Path = mocap.SYNTHETIC_PATH,
    num: int = NUM_DEMOS,
    seed: int = SEED,
    only: tuple[str, ...] = (),
) -> list[Path]:
    """Write every task with a synthetic design (or ``only`` those); see :func:`write_task`."""
    out.mkdir(parents=True, exist_ok=True)
    return [write_task(task, out, num, seed) for task in only or designed_tasks()]


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=mocap.SYNTHETIC_PATH, help="output folder")
    parser.add_argument("--num", type=int, default=NUM_DEMOS, help="demonstrations per task")
    parser.add_argument("--seed", type=int, default=SEED, help="random seed")
    parser.add_argument(
        "--task", action="append", choices=designed_tasks(), help="only this task (repeatable)"
    )
    args = parser.parse_args(argv)
    for file in write_all(args.out, args.num, args.seed, tuple(args.task or ())):
        print(f"wrote {file}")


if __name__ == "__main__":
    main()
