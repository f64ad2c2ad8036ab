"""The benchmark scripts keep working (tiny sizes; no timing is asserted)."""

from __future__ import annotations

import jax
import numpy as np

from benchmarks import replay as replay_bench
from mjx_hands.agents.ddpg import replay


def test_replay_benchmark_runs_both_buffers_at_capacity():
    assert replay_bench.ring_buffer_insert_seconds(256, 64, repeats=1) > 0
    assert replay_bench.brax_queue_insert_seconds(256, 64, repeats=1) > 0


def test_ring_buffer_full_insert_keeps_the_newest_capacity_transitions():
    """What the benchmark times is correct: after many inserts the buffer holds exactly
    the newest ``capacity`` transitions, in ring order."""
    batch = replay_bench._batch(64)
    numbered = batch.replace(reward=np.arange(64, dtype=np.float32))
    buffer = replay.create(100, jax.tree.map(lambda x: x[0], batch))
    for i in range(5):  # 320 transitions into 100 slots
        buffer = replay.insert(buffer, numbered.replace(reward=numbered.reward + 64 * i))
    ids = np.asarray(buffer.data.reward)
    assert sorted(ids) == list(range(220, 320))
    assert ids[int(buffer.position) - 1] == 319
