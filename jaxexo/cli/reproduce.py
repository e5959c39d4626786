"""``jaxexo reproduce``: the seven thesis configs trained and tabulated beside the thesis's Tables
3.2-3.11 (faithful and learning variants). Method and results: docs/thesis-reproduction.md."""

from __future__ import annotations

from jaxexo.cli.common import whole


def cmd_reproduce(args) -> int:
    from jaxexo.evaluation.reproduce import check_reproduce_options, run_names, run_reproduce
    from jaxexo.train.devices import use_all_cpu_cores, use_compilation_cache

    models = [m.strip() for m in args.models.split(",") if m.strip()]
    if not models:
        raise ValueError(f"--models: name at least one model, got {args.models!r}")
    run_names(models, args.variant)  # checks --models and --variant before anything trains
    check_reproduce_options(args.out, args.n, args.results, args.population, args.seed)
    use_all_cpu_cores()  # after the checks (NumPy only): a refusal starts no JAX
    use_compilation_cache()
    run_reproduce(
        args.out,
        models,
        n=args.n,
        seed=args.seed,
        include_default=args.default,
        results_dir=args.results,
        variant=args.variant,
        population=args.population,
    )
    print(
        f"wrote {args.out}/reproduce.md, reproduce.json and the run directories under {args.out}/runs"
    )
    return 0


def add_options(r) -> None:
    """The `jaxexo reproduce` options."""
    r.add_argument(
        "--out",
        required=True,
        help="folder for runs/ and reproduce.md/.json (reuses finished runs)",
    )
    r.add_argument("--models", default="a,b,c,1,2,3,final", help="comma-separated thesis models")
    r.add_argument("--n", type=whole, default=1000, help="test scenarios per model")
    r.add_argument("--seed", type=whole, default=0)
    r.add_argument(
        "--variant",
        default="both",
        choices=("faithful", "learns", "both"),
        help="faithful: configs/thesis/<m>.toml as the thesis wrote it; learns: <m>-learns.toml, with "
        "the named switches that make it learn; both (default): side by side",
    )
    r.add_argument(
        "--default", action="store_true", help="also train and tabulate configs/default.toml"
    )
    r.add_argument(
        "--population",
        type=whole,
        help="members per learns model (seeds SEED..SEED+K-1, the best on validation kept; default "
        "4); the faithful configs always train one agent",
    )
    r.add_argument(
        "--results",
        help="also write the tables to this folder as reproduce_<date>_<machine>.json/.md "
        "(e.g. benchmarks/results)",
    )
    r.set_defaults(func=cmd_reproduce)
