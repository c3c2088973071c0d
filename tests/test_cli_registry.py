"""The dispatcher's command map matches what each module registers, and a command loads only its own."""

from __future__ import annotations

import argparse
import importlib
import subprocess
import sys

from services.cli import COMMANDS, modules_for


def test_each_module_registers_exactly_the_commands_the_map_names() -> None:
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="command")
    for module_name, commands in COMMANDS.items():
        before = set(sub.choices)
        importlib.import_module(module_name).register(sub)
        added = set(sub.choices) - before
        extended = set(commands) - added  # commands another module added first and this one extends
        assert added <= set(commands), f"{module_name} registers {sorted(added - set(commands))} not in COMMANDS"
        assert extended <= before, f"{module_name}: {sorted(extended)} named in COMMANDS but registered by none"


def test_a_command_loads_only_its_modules_and_help_loads_all() -> None:
    assert modules_for(["planner", "--help"]) == ["services.planner.cli"]
    assert modules_for(["ar", "calibrate"]) == ["services.ar_client.cli", "services.ar_client.web.cli"]
    assert modules_for(["tablet"]) == ["services.ar_client.cli", "services.ar_client.web.cli"]
    assert modules_for(["--help"]) == list(COMMANDS)
    assert modules_for(["no-such-command"]) == list(COMMANDS)


def test_a_service_start_imports_no_other_service() -> None:
    code = (
        "import sys\n"
        "from services.cli import main\n"
        "try:\n    main(['planner', '--help'])\nexcept SystemExit:\n    pass\n"
        "print(sorted(m for m in sys.modules if m.startswith('services.') and m.count('.') == 1))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == "['services.cli', 'services.planner']"
