"""Special files, as careful Unix tools treat them: an output that is a device, a FIFO or a link to a
file descriptor is written into, never replaced by a regular file; ``-`` is standard output; an
input is read only from a regular file, up to a size cap, and anything else is refused naming the
file and the rule. docs/reliability.md lists these cases.

Device nodes are made only inside the test's temporary folder (as root; skipped otherwise), never
the system's own /dev entries. No training: the CLI runs use CFFTG or a policy made without training.
"""

from __future__ import annotations

import io
import json
import os
import stat
import threading
import warnings
import zipfile

import pytest

from jaxexo.config import ConfigError, load_config
from jaxexo.config.input_files import InputFileError, read_input
from jaxexo.storage.atomic import atomic_write, direct_output

from conftest import ROOT, run_python
from test_reliability_inputs import assert_clean_refusal, make_policy, run_cli

GEN_CFFTG = ("generate", "--method", "cfftg", "--obstacle", "base1")
ROOT_ONLY = pytest.mark.skipif(os.geteuid() != 0, reason="making a device node needs root")


def _fifo_reader(path, out: list):
    """Read a FIFO to its end in a thread (its writer's open blocks until a reader is there)."""

    def run():
        with open(path, "rb") as f:
            out.append(f.read())

    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


# --------------------------------------------------------------------------------------------
# Outputs: written into, never replaced
# --------------------------------------------------------------------------------------------


def test_a_fifo_output_is_written_into_and_stays_a_fifo(tmp_path):
    fifo = tmp_path / "fifo.csv"
    os.mkfifo(fifo)
    got: list = []
    t = _fifo_reader(fifo, got)
    atomic_write(fifo, "a,b\n1,2\n")
    t.join(10)
    assert got == [b"a,b\n1,2\n"]
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fifo.csv"]  # no temporary file left


def test_generate_writes_its_csv_into_a_fifo(tmp_path):
    fifo = tmp_path / "fifo.csv"
    os.mkfifo(fifo)
    got: list = []
    t = _fifo_reader(fifo, got)
    from jaxexo.cli import main

    assert main([*GEN_CFFTG, "--out", str(fifo)]) in (0, 1)
    t.join(10)
    assert got and got[0].startswith(b"time_s,heel_y_m")
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


@ROOT_ONLY
def test_a_device_node_output_is_written_into_and_stays_a_device(tmp_path):
    null = tmp_path / "null"
    os.mknod(null, 0o666 | stat.S_IFCHR, os.makedev(1, 3))  # the null device, inside tmp_path
    before = os.lstat(null)
    from jaxexo.cli import main

    assert main([*GEN_CFFTG, "--out", str(null), "--json", str(tmp_path / "t.json")]) in (0, 1)
    after = os.lstat(null)
    assert (
        stat.S_ISCHR(after.st_mode)
        and after.st_rdev == before.st_rdev
        and after.st_ino == before.st_ino
    )
    assert json.loads((tmp_path / "t.json").read_text())["method"] == "cfftg"


def test_a_link_to_a_file_descriptor_is_written_through_and_kept(tmp_path):
    r, w = os.pipe()
    link = tmp_path / "so.json"
    link.symlink_to(f"/proc/self/fd/{w}")
    assert direct_output(link)
    atomic_write(link, '{"x": 1}\n')
    os.close(w)
    with os.fdopen(r, "rb") as f:
        assert f.read() == b'{"x": 1}\n'
    assert link.is_symlink() and os.readlink(link) == f"/proc/self/fd/{w}"


def test_a_link_to_a_regular_file_is_still_replaced_not_written_through(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    link = tmp_path / "out.csv"
    link.symlink_to(victim)
    assert not direct_output(link)
    atomic_write(link, "new\n")
    assert (
        victim.read_text() == "precious\n" and not link.is_symlink() and link.read_text() == "new\n"
    )


@pytest.mark.parametrize("target", ["-", "/dev/stdout"])
def test_standard_output_takes_the_data_and_messages_go_to_stderr(tmp_path, target):
    r = run_cli(*GEN_CFFTG, "--out", target, timeout=120)
    assert r.returncode in (0, 1), r.stderr[-2000:]
    assert r.stdout.startswith("time_s,heel_y_m"), r.stdout[:200]
    assert "wrote" in r.stderr and "wrote" not in r.stdout
    assert not (ROOT / "-").exists()


def test_a_figure_is_written_into_a_fifo(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jaxexo.storage.atomic import write_figure

    fifo = tmp_path / "plot.csv"  # a suffix that is no image format: PNG into a special output
    os.mkfifo(fifo)
    got: list = []
    t = _fifo_reader(fifo, got)
    fig = plt.figure(figsize=(1, 1))
    write_figure(fifo, fig, dpi=20)
    plt.close(fig)
    t.join(10)
    assert got[0].startswith(b"\x89PNG")


# --------------------------------------------------------------------------------------------
# Inputs: regular files only, with a cap
# --------------------------------------------------------------------------------------------


def test_a_fifo_folder_or_link_loop_input_is_refused_naming_the_rule(tmp_path):
    fifo = tmp_path / "c.toml"
    os.mkfifo(fifo)  # no writer: an open without O_NONBLOCK would wait forever
    with pytest.raises(InputFileError, match="c.toml: a FIFO .*not a regular file"):
        load_config(fifo)
    with pytest.raises(InputFileError, match="a folder, not a regular file"):
        load_config(tmp_path)
    loop = tmp_path / "loop.toml"
    loop.symlink_to(loop)
    with pytest.raises(InputFileError, match="symbolic link loop"):
        load_config(loop)


@ROOT_ONLY
def test_a_zero_device_as_config_is_refused_before_reading(tmp_path):
    zero = tmp_path / "zero"
    os.mknod(zero, 0o666 | stat.S_IFCHR, os.makedev(1, 5))  # like /dev/zero, inside tmp_path
    with pytest.raises(InputFileError, match="a character device, not a regular file"):
        load_config(zero)
    r = run_cli("train", zero, "--out", tmp_path / "d", "--quiet", timeout=120)
    assert_clean_refusal(r, str(zero), "character device")
    assert not (tmp_path / "d").exists()


def test_a_file_above_its_cap_is_refused_by_its_size(tmp_path):
    big = tmp_path / "big.toml"
    with open(big, "wb") as f:
        f.truncate(17 * 2**20)  # sparse: no 17 MiB written
    with pytest.raises(
        InputFileError, match=r"17,825,792 bytes, more than the 16,777,216 bytes a config may have"
    ):
        load_config(big)
    with pytest.raises(InputFileError, match="more than the 100 bytes"):
        read_input(big, "thing", 100)


@pytest.mark.parametrize("kind", ["folder", "fifo", "loop", "missing"])
def test_a_policy_that_is_no_regular_file_is_named_for_what_it_is(tmp_path, kind):
    p = tmp_path / "policy.npz"
    expected = {
        "folder": "a folder",
        "fifo": "a FIFO",
        "loop": "symbolic link loop",
        "missing": "no such policy",
    }
    if kind == "folder":
        p.mkdir()
    elif kind == "fifo":
        os.mkfifo(p)
    elif kind == "loop":
        p.symlink_to(p)
    r = run_cli(
        "generate", "--policy", p, "--obstacle", "base1", "--out", tmp_path / "t.csv", timeout=120
    )
    assert_clean_refusal(r, "policy.npz", expected[kind])


def test_a_sweep_file_that_is_a_fifo_is_refused(tmp_path):
    from jaxexo.sweep.spec import load_sweep

    fifo = tmp_path / "s.toml"
    os.mkfifo(fifo)
    with pytest.raises(ConfigError, match="s.toml: a FIFO"):
        load_sweep(fifo)


def test_a_config_with_a_byte_order_mark_loads_as_without(tmp_path):
    text = (ROOT / "configs" / "quick.toml").read_text()
    bom = tmp_path / "bom.toml"
    bom.write_bytes(b"\xef\xbb\xbf" + text.encode())
    assert load_config(bom) == load_config(ROOT / "configs" / "quick.toml")


def test_a_policy_archive_with_a_duplicated_member_is_refused_saying_so(tmp_path):
    good = make_policy(tmp_path / "good.npz")
    bad = tmp_path / "dup.npz"
    with zipfile.ZipFile(good) as src, warnings.catch_warnings():
        warnings.simplefilter(
            "ignore"
        )  # zipfile warns about the duplicate name it is asked to write
        with zipfile.ZipFile(bad, "w") as dst:
            for info in src.infolist():
                dst.writestr(info, src.read(info))
            dst.writestr("metadata.npy", src.read("metadata.npy"))
    from jaxexo.storage.policy_file import PolicyFileError, load_policy

    with pytest.raises(PolicyFileError, match="'metadata.npy' more than once"):
        load_policy(bad)


@pytest.mark.parametrize("arg", [None, 3, b"policy.npz", io.BytesIO(b"x")])
def test_generator_load_takes_a_path_only(arg):
    from jaxexo.inference import TrajectoryGenerator

    with pytest.raises(
        TypeError, match=r"path: expected a file's path \(str or os.PathLike\), got"
    ):
        TrajectoryGenerator.load(arg)


def test_a_metrics_log_replaced_by_a_link_is_named_on_resume(tmp_path):
    from jaxexo.train.metrics_log import read_metrics_rows

    victim = tmp_path / "victim.jsonl"
    victim.write_text('{"chunk": 1}\n')
    log = tmp_path / "metrics.jsonl"
    log.symlink_to(victim)
    with pytest.raises(ConfigError, match="metrics.jsonl: is a symbolic link"):
        read_metrics_rows(log, 1)
    assert victim.read_text() == '{"chunk": 1}\n'


# --------------------------------------------------------------------------------------------
# The compilation cache folder and the CLI's warnings
# --------------------------------------------------------------------------------------------


def _cache_warning(monkeypatch, setting) -> str:
    from jaxexo.train import devices

    monkeypatch.setenv(devices.CACHE_ENV, str(setting))
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        assert devices.use_compilation_cache() is None
    return str(w[0].message)


def test_a_cache_path_through_a_link_or_below_a_file_is_refused(tmp_path, monkeypatch):
    real = tmp_path / "real"
    real.mkdir()
    (tmp_path / "link").symlink_to(real)
    msg = _cache_warning(monkeypatch, tmp_path / "link" / "xla")
    assert "link is a symbolic link" in msg
    assert list(real.iterdir()) == []  # nothing written through the link
    (tmp_path / "afile").write_text("x\n")
    msg = _cache_warning(monkeypatch, tmp_path / "afile" / "xla")
    assert "afile is a file, not a folder" in msg and "File exists" not in msg


def test_cli_warnings_are_one_line_without_a_source_line(tmp_path):
    code = (
        "import warnings, sys; from jaxexo import cli; sys.argv = ['jaxexo'];"
        "cli.build_parser = lambda: type('P', (), {'parse_args': lambda self, a: type('A', (), "
        "{'func': staticmethod(lambda args: (warnings.warn('careful'), 0)[1])})()})();"
        "sys.exit(cli.main([]))"
    )
    r = run_python(code, timeout=60)
    assert r.returncode == 0, r.stderr
    assert r.stderr.strip() == "jaxexo: warning: careful"


@pytest.mark.skipif(
    os.geteuid() == 0, reason="root writes through any permission; needs a non-root user"
)
def test_a_cache_folder_that_cannot_be_written_is_a_warning_not_a_crash(tmp_path, monkeypatch):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        msg = _cache_warning(monkeypatch, locked / "xla")
    finally:
        locked.chmod(0o700)
    assert "cannot use" in msg and "Permission denied" in msg and not (locked / "xla").exists()
