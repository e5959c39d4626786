"""``jaxexo eval``: the RL generator (and CFFTG) evaluated side by side on the thesis's scenarios,
the training distribution or the unseen families; report.md/.json and figures. docs/generation.md."""

from __future__ import annotations

from jaxexo.cli.common import Registered, whole


def cmd_eval(args) -> int:
    from jaxexo.evaluation.compare import check_eval_counts, check_report_folder, run_eval

    check_eval_counts(args.n, args.batch)
    check_report_folder(args.out, args.policy, force=args.force)
    report = run_eval(
        args.policy,
        args.out,
        against=args.against,
        scenarios=args.scenarios,
        n=args.n,
        figures=not args.no_figures,
        batch_size=args.batch,
        force=args.force,
        replay=args.replay,
    )
    for name, r in report.items():
        print(
            f"{name}: accuracy {r['accuracy']:.3f}, success {r['success']:.3f}, median {r['time_ms_median']:.3f} ms "
            f"per trajectory, {r['batch_1000_ms']:.1f} ms per batch of 1000"
        )
    print(
        f"wrote {args.out}/report.md, report.json"
        + ("" if args.no_figures else ", trajectories.png, joint_angles.png")
    )
    return 0


def add_options(e) -> None:
    """The `jaxexo eval` options."""
    e.add_argument("--policy", required=True, help="policy.npz written by jaxexo train")
    e.add_argument(
        "--against",
        choices=Registered(lambda cls: not cls.needs_policy),
        help="also evaluate this baseline on the same scenarios",
    )
    e.add_argument(
        "--scenarios",
        choices=("train", "test", "all", "unseen"),
        default="test",
        help="test: the five thesis obstacles x three pivots; train: the policy's training "
        "distribution; all: both; unseen: the fixed held-out obstacle families "
        "(jaxexo.evaluation.unseen), reported per family",
    )
    e.add_argument("--n", type=whole, default=1000, help="scenarios per set")
    e.add_argument(
        "--batch",
        type=whole,
        default=1000,
        help="scenarios per timed generate_batch call (reported scaled to a batch of 1000)",
    )
    e.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    e.add_argument("--force", action="store_true", help="replace an earlier report in --out")
    e.add_argument(
        "--replay",
        action="store_true",
        help="also replay every swing in MuJoCo, kinematically and "
        "driven at the [device] limits (needs the sim extra)",
    )
    e.add_argument("--out", required=True, help="report folder")
    e.set_defaults(func=cmd_eval)
