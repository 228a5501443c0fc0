"""What a study ran on: the fastvi version, the machine and the packages, for the page's header.

A generated page names these instead of a date, so that a reader can tell which code and
which machine its numbers belong to.
"""

from __future__ import annotations

import os
import platform
import subprocess
from importlib import metadata
from pathlib import Path

#: the packages named on a page when installed (the optional ones are left out when missing)
PACKAGES = ("numba", "numpy", "scipy", "CyRK")


def cpu_model() -> str:
    """The processor's name (Linux: ``/proc/cpuinfo``), else :func:`platform.processor`, else
    the architecture."""
    try:
        for line in Path("/proc/cpuinfo").read_text(encoding="utf-8", errors="replace").splitlines():
            if line.lower().startswith("model name"):
                return " ".join(line.split(":", 1)[1].split())
    except OSError:
        pass
    return platform.processor() or platform.machine()


#: the folders whose sources make the numbers: a change elsewhere (the pages and figures a
#: study writes as it goes) does not mark the checkout dirty
CODE = ("fastvi", "studies")


def fastvi_version() -> str:
    """``fastvi.__version__``, and ``git describe`` of the checkout it was imported from
    (where there is one): the commit the numbers belong to, ``-dirty`` when the code
    (:data:`CODE`) differs from it."""
    import fastvi

    root = Path(fastvi.__file__).resolve().parent.parent
    try:
        described = subprocess.run(["git", "describe", "--tags", "--always"],
                                   cwd=root, capture_output=True, text=True, timeout=10)
        changed = subprocess.run(["git", "diff", "--quiet", "HEAD", "--", *CODE],
                                 cwd=root, capture_output=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return fastvi.__version__
    tag = described.stdout.strip() if described.returncode == 0 else ""
    if tag and changed.returncode == 1:
        tag += "-dirty"
    return f"{fastvi.__version__} (git {tag})" if tag else fastvi.__version__


def environment(packages=PACKAGES) -> str:
    """One line: the fastvi version, the CPU and its cores, Python and the installed
    ``packages`` with their versions."""
    versions = []
    for name in packages:
        try:
            versions.append(f"{name} {metadata.version(name)}")
        except metadata.PackageNotFoundError:
            continue
    return (f"fastvi {fastvi_version()}; {cpu_model()}, {os.cpu_count()} cores, "
            f"{platform.system()} {platform.machine()}; Python {platform.python_version()}, "
            + ", ".join(versions))
