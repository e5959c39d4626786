"""jaxexo.storage.atomic: the one atomic write used by the driver, the policy file, sweeps and exports."""

import os

import pytest

from jaxexo.storage import atomic


def test_writes_and_replaces(tmp_path):
    p = tmp_path / "sub" / "f.json"
    atomic.atomic_write(p, "one")
    assert p.read_text() == "one"
    atomic.atomic_write(p, b"two")
    assert p.read_bytes() == b"two"
    assert sorted(os.listdir(p.parent)) == ["f.json"]


@pytest.mark.parametrize("exc", [OSError("disk full"), KeyboardInterrupt()])
def test_failure_keeps_the_old_file_and_removes_the_temp(tmp_path, monkeypatch, exc):
    p = tmp_path / "f.bin"
    p.write_bytes(b"good")

    def fail(fd):
        raise exc

    monkeypatch.setattr(atomic.os, "fsync", fail)
    with pytest.raises(type(exc)):
        atomic.atomic_write(p, b"half")
    assert p.read_bytes() == b"good"
    assert os.listdir(tmp_path) == ["f.bin"]


def test_every_writer_uses_it():
    """The four writers that used to carry their own copy call this one."""
    from jaxexo.storage import policy_file
    from jaxexo.sweep import results
    from jaxexo.swing import export
    from jaxexo.train import checkpoints

    assert results.atomic_write is atomic.atomic_write
    assert export.atomic_write is atomic.atomic_write
    assert policy_file.atomic_write is atomic.atomic_write
    assert checkpoints.checkpoint_write is atomic.atomic_write
