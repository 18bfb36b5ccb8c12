"""Command line: `python -m survey <command>`."""
from __future__ import annotations

import argparse
import sys


def _bench(args):
    from . import bench
    bench.run(t_final=args.t_final, t_scipy=args.t_scipy, repeats=args.repeats)
    return 0


def build_parser():
    parser = argparse.ArgumentParser(prog="python -m survey",
                                     description="Order and chaos in triplet-interaction "
                                                 "Hamiltonian systems.")
    sub = parser.add_subparsers(dest="command", required=True)
    b = sub.add_parser("bench", help="survey's DOP853 vs scipy and heyoka on the paper's orbits")
    b.add_argument("--t-final", type=float, default=2000.0)
    b.add_argument("--t-scipy", type=float, default=50.0,
                   help="span scipy is run over before extrapolating (default 50)")
    b.add_argument("--repeats", type=int, default=2)
    b.set_defaults(func=_bench)
    return parser


def main(argv=None):
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
