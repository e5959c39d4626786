"""The policy file (jaxexo.storage.policy_file): round trip through export and load, and clear errors
for broken files."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest

from jaxexo.storage.policy_file import FORMAT_VERSION, PolicyFileError, load_policy, policy_checksum

jax = pytest.importorskip("jax")
import jax.numpy as jnp  # noqa: E402

from jaxexo.train import export  # noqa: E402
from jaxexo.train.trainer import Trainer  # noqa: E402

from train_helpers import *  # noqa: F401,F403 (the shared tiny config, helpers and fixtures)
from train_helpers import _npz


@pytest.mark.parametrize("layer_norm", [False, True])
def test_policy_round_trip(tmp_path, layer_norm):
    cfg = tiny_config(layer_norm=layer_norm, hidden=[24, 16, 8])
    trainer = Trainer(cfg)
    d = trainer.env.obs_dim
    params = random_params(trainer.net, d, seed=1)
    path = export.export_policy(tmp_path / "policy.npz", cfg, trainer, params)
    with zipfile.ZipFile(path) as z:  # plain arrays, no pickled objects
        assert all(n.endswith(".npy") for n in z.namelist())
    pol = load_policy(path)
    assert pol.obs_dim == d and pol.num_actions == 36
    assert (
        pol.metadata["format_version"] == FORMAT_VERSION
        and pol.metadata["layer_norm"] is layer_norm
    )
    assert len(pol.norm_scales) == (3 if layer_norm else 0)
    obs = np.random.default_rng(0).normal(size=(256, d)).astype(np.float32) * 2
    ref = np.asarray(jax.jit(trainer.net.apply)(params, jnp.asarray(obs)))
    q = pol.q_values(obs)
    assert q.shape == (256, 36)
    np.testing.assert_allclose(q, ref, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(pol.q_values(obs[0]), ref[0], rtol=1e-5, atol=1e-5)
    np.testing.assert_array_equal(pol.greedy_action(obs), ref.argmax(-1))
    with pytest.raises(ValueError, match="last dimension"):
        pol.q_values(obs[:, :-1])


# --------------------------------------------------------------------------------------------
# Broken policy files
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def good_policy(tmp_path_factory):
    cfg = tiny_config(hidden=[8], layer_norm=True)
    trainer = Trainer(cfg)
    params = random_params(trainer.net, trainer.env.obs_dim, seed=0)
    path = export.export_policy(tmp_path_factory.mktemp("pol") / "policy.npz", cfg, trainer, params)
    load_policy(path)
    return path


def _rewrite(src, dst, meta=None, fix_checksum=True, **arrays):
    """A copy of the policy file with metadata fields replaced (None: removed) and arrays replaced (None:
    removed); its checksum recomputed unless ``fix_checksum`` is False, so that the check under test is
    the one that refuses the file (tampering without a new checksum is test_reliability's)."""
    files = _npz(src)
    if meta is not None:
        m = json.loads(str(files["metadata"]))
        m.update(meta)
        m = {k: v for k, v in m.items() if v is not None}
        files["metadata"] = np.array(json.dumps(m))
    for k, v in arrays.items():
        if v is None:
            files.pop(k)
        else:
            files[k] = v
    if fix_checksum and "metadata" not in arrays:
        try:
            m = json.loads(str(files["metadata"]))
        except (KeyError, ValueError):
            m = None
        if isinstance(m, dict):
            m["sha256"] = policy_checksum({k: v for k, v in files.items() if k != "metadata"}, m)
            files["metadata"] = np.array(json.dumps(m))
    np.savez(dst, **files)
    return dst


def test_policy_file_errors(good_policy, tmp_path):
    data = good_policy.read_bytes()
    cases = {}
    cases["missing"] = (tmp_path / "nope.npz", "no such policy file")
    (tmp_path / "trunc.npz").write_bytes(data[: len(data) // 2])
    cases["truncated"] = (tmp_path / "trunc.npz", "truncated or corrupt")
    (tmp_path / "empty.npz").write_bytes(b"")
    cases["empty"] = (tmp_path / "empty.npz", "truncated or corrupt")
    (tmp_path / "junk.npz").write_bytes(b"this is not a zip file at all" * 10)
    cases["junk"] = (tmp_path / "junk.npz", "not a readable policy file")
    cases["version"] = (
        _rewrite(good_policy, tmp_path / "v.npz", {"format_version": FORMAT_VERSION + 1}),
        f"format_version {FORMAT_VERSION + 1}",
    )
    cases["format"] = (
        _rewrite(good_policy, tmp_path / "f.npz", {"format": "other"}),
        "format is 'other'",
    )
    k0 = _npz(good_policy)["dense_0_kernel"]
    cases["shape"] = (
        _rewrite(good_policy, tmp_path / "s.npz", dense_0_kernel=k0.T),
        "dense_0 has shapes",
    )
    cases["layers"] = (
        _rewrite(good_policy, tmp_path / "l.npz", {"layers": [5, 8, 36], "obs_dim": 5}),
        "dense_0 has shapes",
    )
    cases["missing_array"] = (
        _rewrite(good_policy, tmp_path / "m.npz", dense_1_bias=None),
        "missing array 'dense_1_bias'",
    )
    cases["nan"] = (
        _rewrite(good_policy, tmp_path / "n.npz", dense_1_bias=np.full(36, np.nan, np.float32)),
        "'dense_1_bias' holds NaN",
    )
    cases["norm"] = (_rewrite(good_policy, tmp_path / "ln.npz", norm_0_scale=None), "norm_0")
    cases["actions"] = (
        _rewrite(good_policy, tmp_path / "a.npz", {"num_actions": 35}),
        "num_actions 35",
    )
    cases["no_meta"] = (_rewrite(good_policy, tmp_path / "nm.npz", metadata=None), "no 'metadata'")
    cases["bad_json"] = (
        _rewrite(good_policy, tmp_path / "bj.npz", metadata=np.array("{not json")),
        "not valid JSON",
    )
    for name, (path, message) in cases.items():
        with pytest.raises(PolicyFileError, match=message):
            load_policy(path)
    # The good file is still good, and loading is NumPy only (no pickle).
    assert load_policy(good_policy).num_actions == 36


def test_policy_file_that_is_a_single_npy_array(tmp_path):
    path = tmp_path / "policy.npz"
    with path.open("wb") as f:
        np.save(f, np.zeros(3, np.float32))
    with pytest.raises(PolicyFileError):  # any other exception, or none, fails the test
        load_policy(path)


def test_policy_metadata_that_is_not_an_object(good_policy, tmp_path):
    path = _rewrite(good_policy, tmp_path / "p.npz", metadata=np.array("[1, 2]"))
    with pytest.raises(PolicyFileError):
        load_policy(path)
