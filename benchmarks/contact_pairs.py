"""MJX's JAX collision pipeline against native MuJoCo's, per geom-pair type, on the
states of contact-rich native episodes.

    python -m benchmarks.contact_pairs --episodes 4 --replay \
        --out benchmarks/physics_agreement/handshake_contacts.json
    python -m benchmarks.contact_pairs --episodes 4 --replay --force-margin 0 \
        --out benchmarks/physics_agreement/handshake_contacts_touching.json

The starts of the transitions ``benchmarks.physics_agreement`` replays (the closing
demonstration follower on native physics: joint positions and the target hand's mocap
pose of the period) are collided by native MuJoCo (``mj_forward`` on the model native
physics steps, ``physics.native_model``) and by MJX's JAX implementation of the same
model (``mjx.forward``), with the scene's MJX contact caps and without them. MJX lists a
fixed number of candidate contacts; the real ones are those native MuJoCo would list:
closer than the pair's margin plus its gap (MuJoCo 3.17 lists contacts from there and
lets those closer than ``includemargin``, the margin, push). Contacts are matched per
geom pair, nearest point first, and reported per geom-type pair (capsule-box, ...):
contacts native MuJoCo lists, of them MJX finds (matched), MJX alone lists, the
unmatched ones that push (``*_active``: closer than their includemargin) or penetrate,
geom pairs whose number of contact points differs, and the distribution of the matched
contacts' differences in distance (m), point (m), normal (degrees) and includemargin.

``--replay`` replays every period on MJX's JAX implementation as ``physics_agreement``
does and reports the joint-angle differences from native; with ``--force-margin 0`` the
scene's contacts push from touching on (``SceneConfig.force_margin``), in the native
episodes and in both models, and contacts are still listed from ``contact_distance``.
"""

from __future__ import annotations

import argparse
import copy
import json
import time
from collections import Counter
from pathlib import Path

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from benchmarks import machine
from benchmarks.physics_agreement import (
    add_follower_arguments,
    follower_env,
    jax_periods,
    native_transitions,
    summary,
)
from mjx_hands import physics, scene

# A contact list is a dict of arrays: geom (n, 2) ids, dist (n,) m, pos (n, 3) m,
# normal (n, 3) unit, from geom[:, 0] towards geom[:, 1], includemargin (n,) m.


def native_contacts(model: mujoco.MjModel, qpos, mocap_pos, mocap_quat) -> list[dict]:
    """The contact lists native MuJoCo finds at S states: qpos (S, nq), mocap_pos
    (S, nmocap, 3), mocap_quat (S, nmocap, 4)."""
    data = mujoco.MjData(model)
    found = []
    for q, mp, mq in zip(qpos, mocap_pos, mocap_quat, strict=True):
        data.qpos[:], data.mocap_pos[:], data.mocap_quat[:] = q, mp, mq
        mujoco.mj_forward(model, data)
        c = data.contact
        found.append(
            {
                "geom": np.array(c.geom, int).reshape(-1, 2),
                "dist": np.array(c.dist, float),
                "pos": np.array(c.pos, float).reshape(-1, 3),
                "normal": np.array(c.frame, float).reshape(-1, 9)[:, :3],
                "includemargin": np.array(c.includemargin, float),
            }
        )
    return found


def mjx_contacts(
    model: mujoco.MjModel, qpos, mocap_pos, mocap_quat, caps: bool = True
) -> list[dict]:
    """The contact lists MJX's JAX implementation finds at the S states of
    :func:`native_contacts` (float32): of its fixed (ncon,) candidates per state, those
    closer than their pair's margin plus gap (where native MuJoCo lists them). ``caps``:
    the model's ``max_geom_pairs`` / ``max_contact_points``; False: none."""
    uncapped = copy.copy(model)
    if not caps:
        for name in ("max_geom_pairs", "max_contact_points"):
            i = mujoco.mj_name2id(uncapped, mujoco.mjtObj.mjOBJ_NUMERIC, name)
            if i >= 0:
                uncapped.numeric_data[uncapped.numeric_adr[i]] = -1
    mx = physics.put_model(uncapped)  # the training physics' MJX model: collisions, no sensors
    template = mjx.make_data(mx)

    @jax.jit
    @jax.vmap
    def collide(q, mp, mq):
        with jax.default_matmul_precision("highest"):
            c = mjx.forward(mx, template.replace(qpos=q, mocap_pos=mp, mocap_quat=mq))._impl.contact
        return c.geom, c.dist, c.pos, c.frame[:, 0, :], c.includemargin

    states = (jnp.asarray(a, jnp.float32) for a in (qpos, mocap_pos, mocap_quat))
    geom, dist, pos, normal, margin = (np.asarray(a) for a in collide(*states))
    reach = {
        frozenset((int(a), int(b))): float(mg + gap)
        for a, b, mg, gap in zip(
            model.pair_geom1, model.pair_geom2, model.pair_margin, model.pair_gap, strict=True
        )
    }
    limit = np.array([[reach[frozenset(map(int, g))] for g in row] for row in geom])
    found = []
    for s in range(len(geom)):
        real = dist[s] < limit[s]
        found.append(
            {
                "geom": geom[s][real].astype(int),
                "dist": dist[s][real].astype(float),
                "pos": pos[s][real].astype(float),
                "normal": normal[s][real].astype(float),
                "includemargin": margin[s][real].astype(float),
            }
        )
    return found


def by_pair(contacts: dict) -> dict[tuple[int, int], list[int]]:
    """Indices of a contact list's contacts per geom pair (lower geom id first)."""
    pairs: dict[tuple[int, int], list[int]] = {}
    for i, (a, b) in enumerate(contacts["geom"]):
        pairs.setdefault((int(min(a, b)), int(max(a, b))), []).append(i)
    return pairs


def oriented_normal(contacts: dict, i: int) -> np.ndarray:
    """Contact i's normal (3,) pointing from its lower geom id to its higher."""
    a, b = contacts["geom"][i]
    return contacts["normal"][i] * (1.0 if a <= b else -1.0)


def match(native: dict, other: dict) -> list[dict]:
    """Per geom pair of either contact list: its ``pair`` (lower id first), the indices of
    its ``matched`` (native i, other j) contacts (greedily, nearest points first),
    ``missed`` native and ``extra`` other indices."""
    a, b = by_pair(native), by_pair(other)
    rows = []
    for pair in sorted(a.keys() | b.keys()):
        left, right = a.get(pair, []), b.get(pair, [])
        far = np.linalg.norm(
            native["pos"][left][:, None, :] - other["pos"][right][None, :, :], axis=-1
        ).reshape(len(left), len(right))
        matched = []
        for _ in range(min(len(left), len(right))):
            i, j = np.unravel_index(np.argmin(far), far.shape)
            matched.append((left[i], right[j]))
            far[i, :], far[:, j] = np.inf, np.inf
        rows.append(
            {
                "pair": pair,
                "matched": matched,
                "missed": [i for i in left if i not in {m for m, _ in matched}],
                "extra": [j for j in right if j not in {m for _, m in matched}],
            }
        )
    return rows


def type_name(geom_type: np.ndarray, pair: tuple[int, int]) -> str:
    """'capsule-box' etc.: the pair's geom types (``geom_type`` (ngeom,)), in
    ``mjtGeom`` order (the order collision functions take them)."""
    types = sorted(int(geom_type[g]) for g in pair)
    return "-".join(mujoco.mjtGeom(t).name.removeprefix("mjGEOM_").lower() for t in types)


def tally(geom_type: np.ndarray, native: list[dict], other: list[dict]) -> dict[str, dict]:
    """Per geom-type pair, over S states' contact lists ``native`` and ``other`` (S each):
    contact counts, geom pairs whose point counts differ, and the matched contacts'
    differences (see module docstring)."""
    acc: dict[str, dict] = {}
    for nat, oth in zip(native, other, strict=True):
        for row in match(nat, oth):
            t = acc.setdefault(type_name(geom_type, row["pair"]), {"points": Counter()})
            for k in ("dist", "pos", "normal_deg", "includemargin"):
                t.setdefault(k, [])
            missed = [nat["dist"][i] - nat["includemargin"][i] for i in row["missed"]]
            extra = [oth["dist"][j] - oth["includemargin"][j] for j in row["extra"]]
            counts = {
                "pairs": 1,
                "native": len(row["matched"]) + len(row["missed"]),
                "found": len(row["matched"]),
                "extra": len(row["extra"]),
                "missed_active": sum(d < 0 for d in missed),
                "extra_active": sum(d < 0 for d in extra),
                "missed_penetrating": sum(nat["dist"][i] < 0 for i in row["missed"]),
                "extra_penetrating": sum(oth["dist"][j] < 0 for j in row["extra"]),
            }
            for k, v in counts.items():
                t[k] = t.get(k, 0) + int(v)
            n_oth = len(row["matched"]) + len(row["extra"])
            if counts["native"] != n_oth:
                t["points"][f"native {counts['native']} / mjx {n_oth}"] += 1
            for i, j in row["matched"]:
                t["dist"].append(abs(nat["dist"][i] - oth["dist"][j]))
                t["pos"].append(np.linalg.norm(nat["pos"][i] - oth["pos"][j]))
                cos = np.dot(oriented_normal(nat, i), oriented_normal(oth, j))
                t["normal_deg"].append(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
                t["includemargin"].append(abs(nat["includemargin"][i] - oth["includemargin"][j]))
    out = {}
    for name, t in sorted(acc.items()):
        out[name] = {k: v for k, v in t.items() if isinstance(v, int)}
        out[name]["missed"] = t["native"] - t["found"]
        out[name]["pairs_points_differ"] = sum(t["points"].values())
        out[name]["points_differ"] = dict(t["points"].most_common())
        for k in ("dist", "pos", "normal_deg", "includemargin"):
            out[name][k] = summary(np.asarray(t[k], float))
    return out


COLUMNS = ("native", "found", "missed", "missed_active", "missed_penetrating", "extra",
           "extra_active", "pairs_points_differ")  # fmt: skip


def print_table(pairs: dict[str, dict]) -> None:
    print(f"{'pair type':16s}" + "".join(f"{c:>20s}" for c in COLUMNS))
    for name, t in pairs.items():
        print(f"{name:16s}" + "".join(f"{t[c]:>20d}" for c in COLUMNS))
    print(f"{'matched: median / p90 / max':28s}{'|d dist| m':>28s}{'|d pos| m':>28s}"
          f"{'normal deg':>28s}{'|d includemargin| m':>28s}")  # fmt: skip
    for name, t in pairs.items():
        cells = (f"{t[k]['median']:.1e} / {t[k]['p90']:.1e} / {t[k]['max']:.1e}"
                 for k in ("dist", "pos", "normal_deg", "includemargin"))  # fmt: skip
        print(f"{name:28s}" + "".join(f"{c:>28s}" for c in cells))
    for name, t in pairs.items():
        if t["points_differ"]:
            print(f"{name}: geom pairs whose points differ: {t['points_differ']}")


def replay(env, model: mujoco.MjModel, t: dict[str, np.ndarray]) -> dict:
    """``physics_agreement``'s replay of every period on MJX's JAX implementation of
    ``model``: the largest joint-angle difference from native (rad), by contact."""
    qpos, rate = jax_periods(model, env.n_substeps, t)
    diff = np.abs(qpos - t["qpos_after"]).max(axis=1)
    out = {
        "contact": summary(diff[t["contact"]]),
        "free": summary(diff[~t["contact"]]),
        "periods_per_second": rate,
    }
    c, f = out["contact"], out["free"]
    print(f"replay: max |dq| after a period, free ({f['n']}): median {f['median']:.1e}, max "
          f"{f['max']:.1e}; in contact ({c['n']}): median {c['median']:.1e}, p90 "
          f"{c['p90']:.1e}, max {c['max']:.1e} rad", flush=True)  # fmt: skip
    return out


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_follower_arguments(parser, episodes=4)
    parser.add_argument(
        "--force-margin",
        type=float,
        default=scene.SceneConfig.force_margin,
        help="the scene's force margin: distance (m) from which contacts push",
    )
    parser.add_argument("--replay", action="store_true", help="also replay every period on MJX")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)

    env = follower_env(args, scene.SceneConfig(force_margin=args.force_margin))
    print(f"native: {args.episodes} follower episodes ...", flush=True)
    t = native_transitions(env, args.episodes, args.close, args.seed)
    model = physics.native_model(env.mj_model, env.config.contact_distance)
    states = (t["qpos"], t["mocap_pos"], t["mocap_quat"])
    native = native_contacts(model, *states)
    record = {
        "machine": machine.describe(),
        "versions": machine.versions(),
        "task": args.task,
        "episodes": args.episodes,
        "close": args.close,
        "seed": args.seed,
        "mocap_source": args.mocap_source,
        "contact_distance": env.config.contact_distance,
        "force_margin": args.force_margin,
        "pair_margin": float(model.pair_margin.max()),
        "pair_gap": float(model.pair_gap.max()),
        "states": len(t["qpos"]),
        "states_native_contact": int(sum(len(c["dist"]) > 0 for c in native)),
        "mjx": {},
    }
    for name, caps in (("scene_caps", True), ("uncapped", False)):
        print(f"\nMJX (JAX), {name}: collisions of {len(t['qpos'])} states ...", flush=True)
        start = time.perf_counter()
        other = mjx_contacts(model, *states, caps=caps)
        pairs = tally(model.geom_type, native, other)
        record["mjx"][name] = {
            "seconds_with_compile": time.perf_counter() - start,
            "states_contact": int(sum(len(c["dist"]) > 0 for c in other)),
            "pair_types": pairs,
        }
        print_table(pairs)
    if args.replay:
        record["replay"] = replay(env, model, t)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(record, indent=2))
    return record


if __name__ == "__main__":
    main()
