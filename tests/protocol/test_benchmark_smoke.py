"""benchmarks/protocol.py runs end to end and prints the JSON it promises (a short run: the figures
themselves are for `make bench`)."""

from __future__ import annotations

import json
import statistics
import subprocess
import sys

import pytest

from tests.procs import ROOT

pytestmark = [pytest.mark.integration, pytest.mark.slow]


def test_protocol_benchmark_prints_its_json():
    result = subprocess.run(
        [sys.executable, "benchmarks/protocol.py", "--quick", "--runs", "2", "--pings", "200", "--batch", "20"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)  # stdout is the JSON alone; progress went to stderr
    assert "[protocol bench]" in result.stderr
    for name in ("RobotPose", "Intent200"):
        codec = report["codec"][name]
        assert 0 < codec["encode_us"] and 0 < codec["decode_us"] and 0 < codec["encode_decode_us"]
    assert report["codec"]["Intent200"]["bytes"] > report["codec"]["RobotPose"]["bytes"]
    latency = report["latency"]
    assert latency["shared_memory"] is False
    assert latency["raw_payload_bytes"] == latency["payload_bytes"]  # the raw side sends as much
    # raw, the protocol at both ends, and each end alone against a raw other end
    for variant in ("protocol", "protocol_worker", "raw", "protocol_sender", "protocol_echo"):
        figures = latency[variant]
        assert figures["received"] == figures["sent"] == 200
        assert 0 < figures["p50_us"] <= figures["p99_us"]
    assert latency["protocol_over_raw_p50"] == pytest.approx(
        latency["protocol"]["p50_us"] / latency["raw"]["p50_us"], rel=0.01
    )
    # Two runs, each with its own echo processes; the floor is checked on the median of their ratios.
    assert latency["runs"] == len(latency["per_run"]) == 2
    for name in ("protocol", "protocol_worker", "protocol_sender", "protocol_echo"):
        per_run = [run[f"{name}_over_raw_p50_paired"] for run in latency["per_run"]]
        assert all(r > 0 for r in per_run)
        assert latency[f"{name}_over_raw_p50_runs_median"] == pytest.approx(statistics.median(per_run), abs=0.002)
    floors = report["floors"]
    assert floors["protocol_over_raw_p50"] == latency["protocol_over_raw_p50_runs_median"]
    assert floors["protocol_over_raw_p50_pooled"] == latency["protocol_over_raw_p50"]
    assert floors["ratio_met"] == (floors["protocol_over_raw_p50"] <= floors["protocol_over_raw_p50_max"])
    assert floors["met"] == (floors["ratio_met"] and floors["codec_met"])
    assert floors["codec_met"]  # a pose encode+decode in well under 20 µs holds even on a busy machine
