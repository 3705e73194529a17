"""Check a symmetry declaration against its simulator from the shell: ``geomdp-check``.

    geomdp-check Reacher-v5 reacher_v5 --group O(2) D8
    geomdp-check InvertedPendulum-v5 my_pendulum.yaml --group D1 --kwarg xml_file=upright.xml
    geomdp-check GeoMDP/PointMass2D-v0            (a built-in task: its own declaration)

Exit status 0 when every group passes, 1 when one fails, 2 for bad input (one line).
"""

from __future__ import annotations

import argparse
import sys

import gymnasium
import yaml

import geomdp_envs  # noqa: F401  (registers the built-in tasks)
from geomdp_envs.check import check_symmetry, declaration_table
from geomdp_envs.declare import declare, shipped_declarations, symmetry_of


def parse_env_kwarg(text: str) -> tuple[str, object]:
    """``target_size=0.03`` -> ("target_size", 0.03): a keyword argument of gymnasium.make
    from the shell, its value read as YAML reads it (numbers, booleans, strings)."""
    name, sep, value = text.partition("=")
    if not sep or not name:
        raise ValueError(f"{text!r} is not KEY=VALUE")
    return name, yaml.safe_load(value)


def _kwarg(text: str) -> tuple[str, object]:
    try:
        return parse_env_kwarg(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="geomdp-check", description=__doc__.splitlines()[0])
    parser.add_argument("env_id", help="a registered Gymnasium id")
    parser.add_argument("declaration", nargs="?",
                        help=f"YAML file or shipped name ({', '.join(shipped_declarations())}); "
                             "omit for a built-in GeoMDP task")
    parser.add_argument("--group", nargs="+", help="groups to check (default: the exact group)")
    parser.add_argument("--trials", type=int, default=64)
    parser.add_argument("--steps", type=int, default=3, help="control steps after each transformed start")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--tolerance", type=float, default=1e-6)
    parser.add_argument("--kwarg", type=_kwarg, action="append", default=[],
                        help="a keyword argument of gymnasium.make, name=value (repeatable)")
    args = parser.parse_args(argv)
    try:
        if args.env_id not in gymnasium.registry:
            raise ValueError(f"unknown environment {args.env_id!r} (not a registered Gymnasium id)")
        env = gymnasium.make(args.env_id, **dict(args.kwarg))
        if args.declaration is not None:
            env = declare(env, args.declaration)
        symmetry = symmetry_of(env)
        if symmetry is None:
            raise ValueError(f"{args.env_id} declares no symmetry: give a declaration "
                             f"(a YAML file, or one of {', '.join(shipped_declarations())})")
        print(declaration_table(env))
        failed = False
        for group in args.group or [symmetry.exact_group]:
            report = check_symmetry(env, group=group, n_trials=args.trials, n_steps=args.steps,
                                    seed=args.seed, tolerance=args.tolerance)
            print(report)
            failed |= not report.passed
    except (ValueError, TypeError, OSError) as err:  # OSError: gymnasium.make(xml_file=<missing>)
        print(f"geomdp-check: error: {err}", file=sys.stderr)
        return 2
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
