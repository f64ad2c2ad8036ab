"""Replay insertion into a full buffer: the project's ring buffer vs Brax's queue.

Brax's ``UniformSamplingQueue`` rolls its whole storage once it is full to make room
at the end (O(capacity) per insert); :mod:`mjx_hands.agents.ddpg.replay` scatters the
batch at ``(position + i) % capacity`` (O(batch)). Both are jitted with the buffer
donated, filled to capacity first, then timed over repeated inserts of one
training iteration's transitions (hand-task shapes: obs 145, action 24).

    python -m benchmarks.replay [--capacities 100000,1000000] [--batch 640] [--out F.json]
"""

from __future__ import annotations

import argparse
import json
import time

import jax
import jax.numpy as jnp

from benchmarks import machine
from mjx_hands.agents.ddpg import replay

OBS, ACT = 145, 24


def _batch(n: int) -> replay.Transition:
    k = jax.random.split(jax.random.PRNGKey(0), 2)
    return replay.Transition(
        obs=jax.random.normal(k[0], (n, OBS)),
        action=jax.random.uniform(k[1], (n, ACT)),
        reward=jnp.ones(n),
        discount=jnp.ones(n),
        next_obs=jax.random.normal(k[0], (n, OBS)),
        last=jnp.zeros(n),
    )


def _time(fn, state, batch, repeats: int) -> float:
    state = fn(state, batch)  # compile + first run
    jax.block_until_ready(state)
    start = time.perf_counter()
    for _ in range(repeats):
        state = fn(state, batch)
    jax.block_until_ready(state)
    return (time.perf_counter() - start) / repeats


def ring_buffer_insert_seconds(capacity: int, batch_size: int, repeats: int) -> float:
    batch = _batch(batch_size)
    example = jax.tree.map(lambda x: x[0], batch)
    insert = jax.jit(replay.insert, donate_argnums=0)
    buffer = replay.create(capacity, example)
    for _ in range(-(-capacity // batch_size)):  # fill to capacity
        buffer = insert(buffer, batch)
    assert int(buffer.size) == capacity
    return _time(insert, buffer, batch, repeats)


def brax_queue_insert_seconds(capacity: int, batch_size: int, repeats: int) -> float:
    from brax.training import replay_buffers

    batch = _batch(batch_size)
    example = jax.tree.map(lambda x: x[0], batch)
    queue = replay_buffers.UniformSamplingQueue(capacity, example, sample_batch_size=256)
    state = queue.init(jax.random.PRNGKey(0))
    insert = jax.jit(queue.insert, donate_argnums=0)
    for _ in range(-(-capacity // batch_size)):
        state = insert(state, batch)
    return _time(insert, state, batch, repeats)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--capacities", default="100000,1000000")
    parser.add_argument("--batch", type=int, default=640, help="transitions per insert")
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--quick", action="store_true", help="tiny sizes, for CI")
    parser.add_argument("--out", default=None, help="JSON output path")
    args = parser.parse_args()
    capacities = [2000] if args.quick else [int(c) for c in args.capacities.split(",")]
    repeats = 3 if args.quick else args.repeats
    rows = []
    for capacity in capacities:
        ours = ring_buffer_insert_seconds(capacity, args.batch, repeats)
        brax = brax_queue_insert_seconds(capacity, args.batch, repeats)
        rows.append(
            {
                "capacity": capacity,
                "batch": args.batch,
                "ring_buffer_ms": 1e3 * ours,
                "brax_queue_ms": 1e3 * brax,
                "speedup": brax / ours,
            }
        )
        print(
            f"capacity {capacity:>9,d}  batch {args.batch}: ring buffer {1e3 * ours:8.3f} ms, "
            f"Brax queue {1e3 * brax:8.3f} ms per insert ({brax / ours:.1f}x)",
            flush=True,
        )
    result = {
        "machine": machine.describe(),
        "versions": machine.versions(),
        "rows": rows,
    }
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=2)


if __name__ == "__main__":
    main()
