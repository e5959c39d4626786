"""Machine facts recorded beside every benchmark figure, and where results are written."""

from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import re
from pathlib import Path

from jaxexo.storage.atomic import atomic_write


def machine_info() -> dict:
    cpu = platform.processor() or platform.machine()
    try:
        text = Path("/proc/cpuinfo").read_text()
        m = re.search(r"model name\s*:\s*(.+)", text)
        if m:
            cpu = m.group(1).strip()
    except OSError:
        pass
    mem_gib = None
    try:
        m = re.search(r"MemTotal:\s*(\d+) kB", Path("/proc/meminfo").read_text())
        mem_gib = round(int(m.group(1)) / 2**20, 1) if m else None
    except OSError:
        pass
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    info = {
        "cpu": cpu,
        "cores": cores,
        "memory_gib": mem_gib,
        "python": platform.python_version(),
        "platform": platform.platform(),
    }
    try:
        import jax

        info["jax"] = jax.__version__
        info["jax_devices"] = [str(d) for d in jax.local_devices()]
    except ImportError:
        pass
    return info


def machine_tag(info: dict) -> str:
    cpu = re.sub(r"[^A-Za-z0-9]+", "-", info["cpu"]).strip("-").lower()[:40]
    return f"{info['cores']}core-{cpu}"


def write_result(name: str, payload: dict, markdown: str, out_dir: str | Path) -> tuple[Path, Path]:
    """Write ``<out_dir>/<name>_<date>_<machine>.json`` and ``.md``; returns both paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    info = payload.setdefault("machine", machine_info())
    date = _dt.date.today().isoformat()
    payload.setdefault("date", date)
    stem = f"{name}_{date}_{machine_tag(info)}"
    jpath, mpath = out / f"{stem}.json", out / f"{stem}.md"
    atomic_write(jpath, json.dumps(payload, indent=2) + "\n")
    atomic_write(
        mpath,
        markdown + f"\n\nMachine: {info['cpu']}, {info['cores']} cores, "
        f"{info.get('memory_gib')} GiB, JAX {info.get('jax', '-')}; {date}.\n",
    )
    return jpath, mpath
