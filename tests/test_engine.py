"""The run engine's pieces that need no training: the one divergence rule, read the same on the host
and inside a program, and the trainer's metric rows read by name.

(The engine's runs are tests/test_driver.py's, tests/test_population.py's and tests/test_reliability.py's.)"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

jax = pytest.importorskip("jax")
import jax.numpy as jnp  # noqa: E402

from jaxexo.train.lanes import finite  # noqa: E402
from jaxexo.train.metrics_log import Counters, chunk_row  # noqa: E402
from jaxexo.train.records import Track  # noqa: E402
from jaxexo.train.trainer import METRICS, UpdateMetrics  # noqa: E402


def _state(params=1.0, target=1.0):
    tree = lambda v: {  # noqa: E731
        "dense": {"kernel": np.full((2, 3), v, np.float32), "bias": np.zeros(3, np.float32)}
    }
    return SimpleNamespace(params=tree(params), target_params=tree(target))


@pytest.mark.parametrize(
    "params, target, loss, ok",
    [
        (1.0, 1.0, 0.5, True),
        (np.nan, 1.0, 0.5, False),
        (
            1.0,
            np.inf,
            0.5,
            False,
        ),  # the target network alone: diverged (the population's and sweep's rule)
        (1.0, 1.0, np.nan, False),
    ],
)
def test_one_rule_on_the_host_and_in_a_program(params, target, loss, ok):
    ts = _state(params, target)
    m = np.zeros((4, len(METRICS)), np.float32)
    m[2, METRICS.index("loss")] = loss
    assert bool(finite(np, ts, m)) is ok
    in_program = jax.jit(lambda p, t, m: finite(jnp, SimpleNamespace(params=p, target_params=t), m))
    assert bool(in_program(ts.params, ts.target_params, m)) is ok


def test_metric_rows_by_name():
    m = UpdateMetrics(**{k: np.arange(3, dtype=np.float32) + i for i, k in enumerate(METRICS)})
    assert METRICS == (
        "episodes",
        "return_sum",
        "successes",
        "accurate",
        "env_steps",
        "loss",
        "q_mean",
        "epsilon",
    )
    row = chunk_row(m, Counters(np.int32(3), np.int32(9), 10), 1, 2.0, 1.0)
    assert row["chunk_episodes"] == 3 and row["loss"] == float(m.loss.sum()) / 3
    assert row["updates"] == 3 and row["episodes"] == 9 and row["env_steps"] == 30


def test_candidates_finished_a_chunk_and_never_diverged():
    track = Track(
        None, np.array([0.5, 0.9, 0.7, -1.0]), np.array([2, 3, 1, 0]), np.array([0, 4, 0, 0])
    )
    assert track.candidates() == [0, 2]


def test_a_checkpoint_of_the_earlier_single_agent_format_is_refused_naming_it(tmp_path):
    """An earlier jaxexo wrote one agent's checkpoint without the agent axis and the per-agent table
    (``members``): refused in one line naming that format, not poured into a state [1, ...]."""
    from flax import serialization

    from jaxexo.storage.checkpoint import CheckpointError, pack_checkpoint
    from jaxexo.train.checkpoints import read_checkpoint

    book = {"seed": 0, "chunks_done": 1, "best_score": 0.5, "best_chunk": 1, "devices": 2}
    payload = {"state": {"update": np.int32(55)}, "best_params": {}, "book": book}
    path = tmp_path / "checkpoint.msgpack"
    path.write_bytes(pack_checkpoint(serialization.msgpack_serialize(payload)))
    with pytest.raises(CheckpointError, match="single-agent format of an earlier jaxexo") as e:
        read_checkpoint(path)
    assert str(e.value).startswith(f"{path}: ") and "\n" not in str(e.value)
