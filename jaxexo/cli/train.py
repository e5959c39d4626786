"""``jaxexo train``: a policy trained (one agent or a population) into a run directory, resumable
after an interruption. Training: docs/training.md."""

from __future__ import annotations

from pathlib import Path

from jaxexo.cli.common import load, whole


def _resume_command(args) -> str:
    """The command line that continues an interrupted ``jaxexo train`` (its options, and --resume)."""
    import shlex

    argv = ["jaxexo", "train"]
    if args.config_given is not None:
        argv.append(str(args.config_given))
    argv += ["--out", str(args.out)]
    if args.seed != 0:
        argv += ["--seed", str(args.seed)]
    if args.population is not None:
        argv += ["--population", str(args.population)]
    return shlex.join([*argv, "--resume"])


def cmd_train(args) -> int:
    from jaxexo.cli.interrupt import honoured
    from jaxexo.storage.rundir import contents

    args.config_given = args.config  # as typed: the resume command repeats it
    try:  # the run directory as it was: only a run this command wrote into can be resumed
        fresh = not contents(Path(args.out))
    except OSError:
        fresh = False  # unreadable: refused by the run's lock, below
    with honoured(lambda: _interrupted(args, fresh)):
        return _train(args)


def _interrupted(args, fresh: bool) -> str:
    """What a Ctrl-C says: how to continue the run, or that nothing was trained yet."""
    if args.resume or (fresh and (Path(args.out) / "config.toml").is_file()):
        return (
            f"jaxexo: interrupted; {args.out} keeps the chunks trained up to its last checkpoint; "
            f"continue it with: {_resume_command(args)}"
        )
    return "jaxexo: interrupted before training started; nothing was trained: run the command again"


def _train(args) -> int:
    from jaxexo.train.devices import use_all_cpu_cores

    use_all_cpu_cores()
    if args.config is None and args.resume and (Path(args.out) / "config.toml").is_file():
        args.config = Path(args.out) / "config.toml"  # the run's own resolved config
    cfg, name = load(args.config)
    if args.population is not None:
        from jaxexo.config import with_population

        cfg = with_population(cfg, args.population, "--population")
    from jaxexo.config import check_seed

    check_seed(
        args.seed, "--seed", cfg.train.population
    )  # before JAX starts (run_training checks it too)
    from jaxexo.config.memory import check_memory

    check_memory(cfg)  # before JAX allocates: a run the machine cannot hold is refused here
    from jaxexo.train.devices import use_compilation_cache

    use_compilation_cache()  # a later run of these static settings loads its programs
    from jaxexo.train.driver import run_training

    k = cfg.train.population
    seeds = (
        f"seeds {args.seed}..{args.seed + k - 1}, population of {k}"
        if k > 1
        else f"seed {args.seed}"
    )
    print(f"jaxexo train: {name} -> {args.out} ({seeds}{', resume' if args.resume else ''})")
    res = run_training(cfg, args.out, seed=args.seed, resume=args.resume, progress=not args.quiet)
    _print_result(res, k, args.out)
    return 0


def _print_result(res: dict, k: int, out) -> None:
    """The trained run's summary: episodes, the greedy evaluation and, for a population, its members."""
    held = res.get("held_out") or {}
    print(
        f"trained {res['episodes']} episodes, {res['env_steps']:,} env steps in {res['train_seconds']:.1f} s"
    )
    print(
        f"greedy eval on {sum(v['n'] for v in res['by_obstacle'].values())} test layouts: "
        f"success_raw {res['success_raw']:.3f}, accuracy {res['accuracy']:.3f}"
        + (f"; held-out triangle/half-circle success_raw {held['success_raw']:.3f}" if held else "")
    )
    if k > 1:
        ok = [m for m in res["members"] if m["diverged_chunk"] is None]
        print(
            f"exported member {res['exported_member']} (seed {res['seed']}, chunk {res['selected_chunk']}, "
            f"validation {res['validation_success_raw']:.3f}); {len(ok)} of {k} members finite, test success_raw "
            + ", ".join(
                f"{m['test']['success_raw']:.2f}" if m["test"] else "-" for m in res["members"]
            )
        )
    print(f"wrote {out}/policy.npz, eval.json, metrics.jsonl, training_curve.png")


def add_options(t) -> None:
    """The `jaxexo train` options."""
    t.add_argument(
        "config",
        nargs="?",
        help="TOML config (default: the packaged default, configs/default.toml; "
        "with --resume, the run's own config.toml)",
    )
    t.add_argument("--out", required=True, help="run directory")
    t.add_argument("--seed", type=whole, default=0)
    t.add_argument(
        "--population",
        type=whole,
        help="train K agents (seeds SEED..SEED+K-1) as one program and export the "
        "one a wearer would choose (overrides [train] population; the "
        "default model's: 2)",
    )
    t.add_argument(
        "--resume", action="store_true", help="continue the run in --out from its checkpoint"
    )
    t.add_argument("--quiet", action="store_true", help="no progress bar")
    t.set_defaults(func=cmd_train)
