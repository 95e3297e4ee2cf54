from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from rozyn_estimator.tools.cli import main

ROOT = Path(__file__).resolve().parents[1]


def test_trial_json_lines(capsys):
    assert main(["trial", "--seeds", "1-3", "--json", "--jobs", "1", "--duration-s", "60"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 3
    records = [json.loads(line) for line in lines]
    assert [r["seed"] for r in records] == [1, 2, 3]
    for r in records:
        assert r["status"] == "ok" and r["reason"] == ""
        assert {"mass_kg", "pitch_inertia_kgm2", "cog_from_front_axle_m", "covariance", "modes"} <= set(r)
        assert len(r["covariance"]) == 3 and all(len(row) == 3 for row in r["covariance"])
        assert {"freq_hz", "damping_ratio"} == set(r["modes"][0])


def test_trial_table(capsys):
    assert main(["trial", "--seeds", "1-4", "--jobs", "2", "--road", "laplace"]) == 0
    out = capsys.readouterr().out
    assert "Laplace road" in out and "pitch inertia" in out and "failures: 0 of 4" in out


def test_free_decay_and_single_seed(capsys):
    assert main(["trial", "--road", "free-decay", "--duration-s", "1", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert abs(r["mass_kg"] / 1000 - 1) < 0.005 and r["covariance"] is None


def test_bad_vehicle_file_is_one_clear_line(tmp_path, capsys):
    bad = tmp_path / "v.yaml"
    bad.write_text("wheelbase_m: -2\n")
    assert main(["trial", "--vehicle", str(bad)]) == 1
    err = capsys.readouterr().err
    assert "wheelbase_m" in err and "Traceback" not in err and err.count("\n") == 1


@pytest.mark.parametrize("args", [["trial", "--seeds", "5-1"], ["trial", "--road-class", "Q"],
                                  ["trial", "--speed-kmh", "-3"]])
def test_bad_options_exit_1(args, capsys):
    assert main(args) == 1
    assert "error" in capsys.readouterr().err


def test_console_script_and_bench():
    exe = Path(sys.executable).parent / "rozyn"
    out = subprocess.run([str(exe), "bench", "--repeats", "2"], capture_output=True, text=True, check=True)
    figures = json.loads(out.stdout)
    for key in ("sim_100s_at_100hz_ms", "road_generation_ms", "update_120s_window_ms",
                "update_120s_window_no_variance_ms", "peak_rss_mb"):
        assert figures[key] > 0


def test_every_command_has_help():
    exe = Path(sys.executable).parent / "rozyn"
    for command in ([], ["trial"], ["demo"], ["bench"], ["replay"], ["study"], ["compare"]):
        done = subprocess.run([str(exe), *command, "--help"], capture_output=True, text=True)
        assert done.returncode == 0 and "usage: rozyn" in done.stdout, (command, done.stderr)
