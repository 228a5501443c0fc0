"""``python -m fastvi``: plain-text help with defaults; studies write where they are told."""

import os
import subprocess
import sys

import pytest

from fastvi.__main__ import COMMANDS, main

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _help(args, capsys):
    with pytest.raises(SystemExit) as info:
        import importlib

        importlib.import_module(COMMANDS[args[0]][0]).main(args[1:])
    assert info.value.code == 0
    return capsys.readouterr().out


def _no_markup(text):
    assert "`" not in text and "::" not in text and ":func:" not in text and ":mod:" not in text, text


def test_top_level_help_is_plain_and_lists_every_command(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    _no_markup(out)
    for name, (_, what) in COMMANDS.items():
        assert f"{name}" in out and what in out


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_command_help_is_plain_with_defaults(command, capsys):
    out = _help([command, "--help"], capsys)
    _no_markup(out)
    options = [ln for ln in out.splitlines() if ln.startswith("  --")]  # not continuation lines
    assert options
    # every option (not -h) states its default, possibly on a continuation line
    body = out.split("options:", 1)[1]
    assert body.count("(default:") == len(options), out


@pytest.mark.parametrize("command, default", [("paper-b", "fastvi-study-paper-b"),
                                              ("wpd", "fastvi-study-wpd"),
                                              ("orders", "fastvi-study-orders/orders.md")])
def test_studies_do_not_default_to_the_package_docs(command, default, capsys):
    # argparse wraps long values after a hyphen: undo that before comparing
    out = " ".join(_help([command, "--help"], capsys).split()).replace("- ", "-")
    assert f"(default: {default})" in out
    assert "(default: docs" not in out


def test_a_study_outside_a_checkout_says_it_needs_one(monkeypatch, capsys):
    """From an installed package (no ``studies/`` folder on the path) a study command says
    where it runs instead of a traceback."""
    import fastvi.__main__ as cli

    real = cli.importlib.import_module

    def installed_only(name, *args):
        if name.split(".")[0] == cli.CHECKOUT_ONLY:
            raise ModuleNotFoundError(f"No module named {cli.CHECKOUT_ONLY!r}", name=cli.CHECKOUT_ONLY)
        return real(name, *args)

    monkeypatch.setattr(cli.importlib, "import_module", installed_only)
    assert main(["wpd", "--help"]) == 2
    err = capsys.readouterr().err
    assert "source checkout" in err and "python -m fastvi wpd" in err


def test_makefile_regenerates_the_package_docs_explicitly():
    with open(os.path.join(ROOT, "Makefile"), encoding="utf-8") as fh:
        text = fh.read()
    assert "-m fastvi paper-b --out docs" in text
    assert "-m fastvi wpd --out docs" in text
    assert "-m fastvi orders --out docs/orders.md" in text


@pytest.mark.slow
def test_paper_b_without_out_writes_into_the_current_directory(tmp_path):
    env = {**os.environ, "PYTHONPATH": ROOT}
    out = subprocess.run([sys.executable, "-m", "fastvi", "paper-b", "--quick", "--quiet", "--no-figures"],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "fastvi-study-paper-b" / "paper-b.md").is_file()
    assert not (tmp_path / "docs").exists()


def test_compile_times_the_first_calls_it_is_asked_for(capsys):
    """``python -m fastvi compile`` runs the first calls it is given (here warm: the
    kernels of this process) and prints one line each; an unknown call is refused by name."""
    from fastvi import warmup

    # two cheap ones (the damped model adds a force to the same kernels)
    records = warmup.first_calls(["integrate", "forces"])
    assert [r["name"] for r in records] == ["integrate", "forces"]
    assert all(r["wall"] > 0 and r["peak_mb"] > 0 for r in records)
    assert main(["compile", "--only", "integrate"]) == 0
    assert "integrate" in capsys.readouterr().out
    with pytest.raises(SystemExit) as info:
        main(["compile", "--only", "integrate,bogus"])
    assert info.value.code == 2 and "bogus" in capsys.readouterr().err
