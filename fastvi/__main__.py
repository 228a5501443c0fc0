"""Command line: python -m fastvi <command> [options].

Each command is a function ``main(argv) -> int`` in a module, imported only when used (so
optional extras such as matplotlib are needed only by the commands that plot). ``compile``
and ``demo`` ship with fastvi; ``paper-b``, ``orders`` and ``wpd`` regenerate pages of the
documentation and run from the root of a source checkout, whose ``studies/`` folder holds
them (they are not installed: docs/decisions/0011-studies-in-the-package.md).
"""

from __future__ import annotations

import argparse
import importlib
import sys

#: command -> (module, one-line description)
COMMANDS = {
    "compile": ("fastvi.warmup", "compile the kernels into the cache, or time a cold first session (--report)"),
    "demo": ("fastvi.studies.demo", "integrate the double pendulum and print a summary"),
    "paper-b": ("studies.paper_b", "reproduce paper B's tables and figures (source checkout)"),
    "orders": ("studies.orders", "measure convergence orders of every combination (source checkout)"),
    "wpd": ("studies.wpd", "work-precision diagrams against RK4, SciPy and CyRK (source checkout)"),
    "lyapunov": ("studies.lyapunov",
                 "Lyapunov exponents of the double pendulum: ensemble, T and h, SciPy reference "
                 "(source checkout)"),
    "sensitivities": ("studies.sensitivities",
                      "cost, order and symplecticity of the flow's derivatives; a parameter fit "
                      "(source checkout)"),
}
#: the package of the commands that run from a source checkout only
CHECKOUT_ONLY = "studies"


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    epilog = "commands:\n" + "\n".join(f"  {k:9s} {v[1]}" for k, v in sorted(COMMANDS.items()))
    epilog += "\n\n'python -m fastvi <command> --help' lists a command's options and their defaults."
    parser = argparse.ArgumentParser(prog="python -m fastvi", description=__doc__.splitlines()[0],
                                     epilog=epilog, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("command", choices=sorted(COMMANDS), help="what to run (see below)")
    if not argv or argv[0] in ("-h", "--help"):
        parser.print_help()
        return 0 if argv else 2
    args = parser.parse_args(argv[:1])
    name = COMMANDS[args.command][0]
    try:
        module = importlib.import_module(name)
    except ModuleNotFoundError as exc:
        if exc.name not in (CHECKOUT_ONLY, name):
            raise
        print(f"python -m fastvi {args.command}: this command regenerates a page of fastvi's "
              "documentation and runs from the root of a source checkout of fastvi (its "
              f"'{CHECKOUT_ONLY}/' folder), not from an installed package: clone the repository, "
              f"cd into it and run 'python -m fastvi {args.command}' there.", file=sys.stderr)
        return 2
    return int(module.main(argv[1:]) or 0)


if __name__ == "__main__":
    sys.exit(main())
