"""``arroch site check|show|generate`` as real processes."""

from __future__ import annotations

import json
import subprocess
import tomllib
from pathlib import Path

import numpy as np
import pytest

from protocol.site import default_site_path, load_site
from tests.procs import ROOT, arroch

BAD = Path(__file__).parent / "bad_sites"


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(arroch(*args), cwd=ROOT, capture_output=True, text=True, timeout=60)


def test_check_prints_a_summary() -> None:
    out = run("site", "check")  # no file: the packaged site, as for every other command
    assert out.returncode == 0, out.stderr
    named = run("site", "check", str(default_site_path())).stdout
    assert out.stdout.splitlines()[1:] == named.splitlines()[1:]  # the same site; only its source differs
    for line in (
        "site office",
        "rooms (9)",
        "doors (6): d_storage (human-operated)",
        "passages (4)",
        "landmarks (33): tags 0-32",
        "robots (3): r0 in corridor",
        "objects (9)",
        "human: in storage",
    ):
        assert line in out.stdout


def test_check_refuses_a_bad_file_with_the_reason() -> None:
    out = run("site", "check", str(BAD / "door_off_edge.toml"))
    assert out.returncode == 2
    assert (
        'door_off_edge.toml: doors[1] (id "d_b"): center (6, 3.3) is not on an edge shared by rooms "c" and "b"'
        in out.stderr
    )
    assert out.stdout == ""
    missing = run("site", "check", "no/such/site.toml")
    assert missing.returncode == 2 and "site.toml: no such site file" in missing.stderr


def test_show_renders_a_png(tmp_path: Path) -> None:
    png = tmp_path / "office.png"
    out = run("site", "show", "--png", str(png), "--dpi", "80")  # the packaged site
    assert out.returncode == 0, out.stderr
    import cv2

    image = cv2.imread(str(png))
    assert image is not None and image.shape[1] > 800 and image.shape[0] > 400
    # Not a blank canvas: the dark wall colour and the human-operated door's red are both drawn.
    assert (np.abs(image.astype(int) - [0x3B, 0x3B, 0x3B]).sum(axis=2) < 30).sum() > 5000
    assert (np.abs(image.astype(int) - [0x28, 0x27, 0xD6]).sum(axis=2) < 40).sum() > 20  # BGR of #d62728
    bad = run("site", "show", str(BAD / "unreachable_room.toml"), "--png", str(tmp_path / "x.png"))
    assert bad.returncode == 2 and "not reachable" in bad.stderr and not (tmp_path / "x.png").exists()


def test_generate_writes_a_valid_deterministic_site(tmp_path: Path) -> None:
    a, b = tmp_path / "a.toml", tmp_path / "b.toml"
    assert run("site", "generate", "--robots", "4", "--objects", "2", "--seed", "9", "--out", str(a)).returncode == 0
    assert run("site", "generate", "--robots", "4", "--objects", "2", "--seed", "9", "--out", str(b)).returncode == 0
    assert a.read_text() == b.read_text()
    site = load_site(a)
    assert len(site.robots) == 4 and len(site.objects) == 8
    assert tomllib.loads(a.read_text())["site"]["name"] == "gen_4x2_s9"
    assert run("site", "check", str(a)).returncode == 0
    bad = run("site", "generate", "--robots", "0")
    assert bad.returncode == 2 and "robots must be an integer >= 1" in bad.stderr


@pytest.mark.parametrize("argv", [("site",), ("site", "show", "x.toml")])
def test_usage_errors_exit_2(argv: tuple[str, ...]) -> None:
    assert run(*argv).returncode == 2


def test_schema_prints_the_json_schema_of_site_files() -> None:
    out = run("site", "schema")
    assert out.returncode == 0, out.stderr
    schema = json.loads(out.stdout)
    defs = schema["$defs"]
    assert schema["$ref"] == "#/$defs/SiteFile"
    assert set(defs["SiteFile"]["required"]) == {"site", "rooms", "robots", "human"}
    assert defs["SiteFile"]["properties"]["robots"]["minItems"] == 1
    door = defs["DoorTable"]["properties"]
    assert door["width"]["exclusiveMinimum"] == 0 and door["center"]["minItems"] == door["center"]["maxItems"] == 2
    assert defs["LandmarkTable"]["properties"]["tag"]["maximum"] == 586
    # Every key the packaged site uses is declared, table by table.
    office = tomllib.loads(default_site_path().read_text(encoding="utf-8"))
    tables = {"site": "SiteTable", "params": "ParamsTable", "human": "HumanTable", "rooms": "RoomTable"}
    tables |= {"doors": "DoorTable", "landmarks": "LandmarkTable", "robots": "RobotTable", "objects": "ObjectTable"}
    for key, name in tables.items():
        entries = office[key] if isinstance(office[key], list) else [office[key]]
        for entry in entries:
            assert set(entry) <= set(defs[name]["properties"]), (key, entry)
