"""Command line: python -m fastvi <command> [options].

Each command is a function ``main(argv) -> int`` in a study module, imported only when used
(so optional extras such as matplotlib are needed only by the commands that plot).
"""

from __future__ import annotations

import argparse
import importlib
import sys

#: command -> (module, one-line description)
COMMANDS = {
    "compile": ("fastvi.warmup", "compile the kernels into the cache, or time a cold first session (--report)"),
    "demo": ("fastvi.studies.demo", "integrate the double pendulum and print a summary"),
    "paper-b": ("fastvi.studies.paper_b", "reproduce paper B's tables and figures"),
    "orders": ("fastvi.studies.orders", "measure convergence orders of every combination (docs/orders.md)"),
    "wpd": ("fastvi.studies.wpd", "work-precision diagrams against RK4 and SciPy"),
    "sensitivities": ("fastvi.studies.sensitivities",
                      "cost, order and symplecticity of the flow's derivatives; a parameter fit"),
}


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
    module = importlib.import_module(COMMANDS[args.command][0])
    return int(module.main(argv[1:]) or 0)


if __name__ == "__main__":
    sys.exit(main())
