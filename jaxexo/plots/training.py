"""The figure of a training run, training_curve.png, the same for one agent and a population
(matplotlib, imported on first use; the run directory: docs/training.md)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from jaxexo.storage.atomic import write_figure


def plot_training_curve(path: Path, rows: list[dict], exported: int | None) -> None:
    """training_curve.png: every member's training success and validation success against its
    episodes (metrics.jsonl's ``rows``); the exported member drawn bold."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    for i in range(len(rows[0]["members"])):
        mem = [r["members"][i] for r in rows]
        ep = [m["episodes"] for m in mem]
        bold = dict(lw=2.2, zorder=3) if i == exported else dict(lw=0.9, alpha=0.6)
        label = f"seed {mem[0]['seed']}" + (" (exported)" if i == exported else "")
        a1.plot(ep, [m["success_raw_rate"] for m in mem], label=label, **bold)
        a2.plot(
            ep,
            [
                np.nan if m["validation_success_raw"] is None else m["validation_success_raw"]
                for m in mem
            ],
            label=label,
            **bold,
        )
    a1.set_ylabel("training strict success\n(behaviour policy)")
    a1.set_title(f"Population of {len(rows[0]['members'])}: training and validation per member")
    a2.set_ylabel("validation strict success\n(greedy, training layouts)")
    a2.set_xlabel("episodes")
    for a in (a1, a2):
        a.set_ylim(-0.02, 1.02)
        a.grid(alpha=0.3)
    a2.legend(loc="lower right", fontsize=7, ncol=2)
    fig.tight_layout()
    write_figure(path, fig, dpi=110)
    plt.close(fig)
