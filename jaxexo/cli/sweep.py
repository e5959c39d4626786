"""``jaxexo sweep``: a grid of configurations x seeds trained as compiled, vmapped programs, on this
machine's cores or a Ray cluster, ranked and exported. Method: docs/training.md."""

from __future__ import annotations

from jaxexo.cli.common import check_count, whole


def cmd_sweep(args) -> int:
    from jaxexo.sweep.plan import check_memory_budget
    from jaxexo.sweep.spec import load_sweep, memory_budget

    check_count(args.task_cpus, "--task-cpus")
    budget = None if args.memory_budget is None else memory_budget(args.memory_budget)
    if budget is not None and args.backend == "local":
        # This machine runs the chunks (a Ray task's budget is its node's memory).
        check_memory_budget(budget, args.memory_budget, "--memory-budget")
    sweep = load_sweep(args.sweep)  # validated (NumPy only) before JAX starts
    if budget is None and sweep.memory_budget is not None and args.backend == "local":
        check_memory_budget(
            sweep.memory_budget,
            f"{sweep.memory_budget / 2**30:.4g} GiB",
            f"{args.sweep}: sweep.memory_budget",
        )
    if args.backend == "local":
        from jaxexo.train.devices import use_all_cpu_cores, use_compilation_cache

        use_all_cpu_cores()
        use_compilation_cache()
    from jaxexo.sweep.runner import run_sweep

    print(
        f"jaxexo sweep: {args.sweep} -> {args.out}: {len(sweep.members)} configurations x {len(sweep.seeds)} "
        f"seeds = {sweep.num_agents} agents in {len(sweep.groups)} group(s) ({args.backend} backend"
        f"{', resume' if args.resume else ''})"
    )
    heatmap = tuple(args.heatmap.split(",")) if args.heatmap else None
    res = run_sweep(
        sweep,
        args.out,
        resume=args.resume,
        backend=args.backend,
        address=args.address,
        memory_budget=budget,
        task_cpus=args.task_cpus,
        progress=not args.quiet,
        export_best=args.export_best,
        export_all=args.export_all,
        heatmap=heatmap,
    )
    for i, e in enumerate(res["ranking"][:5], 1):
        print(
            f"  #{i} config {e['config_id']} ({e['label']}): success {e['success_mean']:.3f} "
            f"± {e['success_std']:.3f} over {e['seeds']} seeds, held-out {e['held_out_success']:.3f}"
            + (f", {e['diverged']} diverged" if e["diverged"] else "")
        )
    if res["wall_s_this_run"] > 0 and res["env_steps_this_run"]:
        print(
            f"{res['env_steps_this_run']:,.0f} env steps in {res['wall_s_this_run']:.1f} s "
            f"({res['env_steps_this_run'] / res['wall_s_this_run'] / 1e6:.3f} M env-steps/s)"
        )
    print(
        f"wrote {args.out}/results.csv, summary.md, "
        + ", ".join(res["figures"])
        + (", best/policy.npz, best/config.toml" if "exported" in res else "")
    )
    return 0


def add_options(s) -> None:
    """The `jaxexo sweep` options."""
    s.add_argument("sweep", help="sweep file (a config with a [sweep] table; see configs/sweeps/)")
    s.add_argument(
        "--out", required=True, help="sweep directory (results.csv, summary.md, figures)"
    )
    s.add_argument(
        "--resume", action="store_true", help="run only the chunks of --out without results"
    )
    s.add_argument(
        "--export-best", action="store_true", help="write best/policy.npz and best/config.toml"
    )
    s.add_argument(
        "--export-all",
        action="store_true",
        help="write every agent's policy.npz and config.toml under agents/ (and agents/index.json)",
    )
    s.add_argument(
        "--backend",
        choices=["local", "ray"],
        default="local",
        help="local: chunks over this machine's CPU cores; ray: chunks as tasks on a Ray cluster",
    )
    s.add_argument("--address", help="Ray cluster address (default: start a local Ray instance)")
    s.add_argument(
        "--task-cpus",
        type=whole,
        help="ray: CPUs (JAX devices) per chunk task (default: this machine's cores)",
    )
    s.add_argument(
        "--memory-budget",
        help="memory for one chunk, e.g. 4GiB (default: half the available memory)",
    )
    s.add_argument(
        "--heatmap",
        help="two axes for heatmap.png, e.g. train.lr,train.lam (default: sweep.heatmap)",
    )
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=cmd_sweep)
