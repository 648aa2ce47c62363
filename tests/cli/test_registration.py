"""Every command exists whatever module is imported first, and ``python -m ratfit`` works."""

from __future__ import annotations

import subprocess
import sys

import pytest

COMMANDS = ["batch", "brdf", "cdf", "demo", "eval", "export", "fit", "plot", "render",
            "report", "sample", "tolerance"]
SUBCOMMANDS = {"brdf": ["compare", "eval", "fit", "merge", "model"], "demo": ["addendum", "cdf"]}
FIRST_IMPORTS = ["ratfit.cli.brdf", "ratfit.cli.export", "ratfit.cli.cdf", "ratfit.cli.batch",
                 "ratfit.cli.demo", "ratfit.cli.tolerance", "ratfit.cli.main", "ratfit.cli.fit",
                 "ratfit"]


@pytest.mark.parametrize("first", FIRST_IMPORTS)
@pytest.mark.slow
def test_all_commands_registered_in_any_import_order(first: str) -> None:
    code = (f"import importlib, json, click; importlib.import_module({first!r}); "
            "from ratfit.cli import main; "
            "ctx = click.Context(main); "
            "cmds = {k: main.get_command(ctx, k) for k in main.list_commands(ctx)}; "
            "print(json.dumps({k: [v.get_command(ctx, s).name for s in v.list_commands(ctx)] "
            "if isinstance(v, click.Group) else [] for k, v in cmds.items()}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    import json

    got = json.loads(out.stdout)
    assert sorted(got) == COMMANDS
    for group, subs in SUBCOMMANDS.items():
        assert got[group] == subs


def test_python_dash_m_lists_every_command() -> None:
    out = subprocess.run([sys.executable, "-m", "ratfit", "--help"], capture_output=True,
                         text=True, check=True).stdout
    listed = [line.split()[0] for line in out.split("Commands:")[1].splitlines() if line.strip()]
    assert listed == COMMANDS
    assert out.startswith("Usage: ratfit ")
