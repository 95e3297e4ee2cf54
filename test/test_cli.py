from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from rozyn_estimator.tools.cli import COMMANDS, main

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


def _tool_modules_after(argv: list[str]) -> list[str]:
    """The rozyn_estimator.tools modules imported by ``main(argv)`` in a fresh interpreter."""
    code = ("import sys\nfrom rozyn_estimator.tools.cli import main\n"
            f"try:\n    main({argv!r})\nexcept SystemExit:\n    pass\n"
            "print(' '.join(sorted(m for m in sys.modules if m.startswith('rozyn_estimator.tools.'))))")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    return done.stdout.split("\n")[-2].split()


def test_top_level_help_imports_no_command():
    assert _tool_modules_after(["--help"]) == ["rozyn_estimator.tools.cli"]


def test_only_the_invoked_command_is_imported():
    loaded = _tool_modules_after(["trial", "--help"])
    assert "rozyn_estimator.tools.trial.command" in loaded
    others = {f"rozyn_estimator.tools.{m}" for m in ("compare", "study", "replay", "demo", "bench")}
    assert not others & set(loaded)


def test_the_registry_matches_the_command_modules():
    assert [c.name for c in COMMANDS] == ["trial", "demo", "bench", "replay", "study", "compare"]
    for command in COMMANDS:
        module = command.load()
        assert command.help == module.HELP, command.name
        assert hasattr(module, "DESCRIPTION") and callable(module.add_arguments) and callable(module.run)


@pytest.mark.parametrize(("args", "words"), [
    (["demo", "--window-s", "5000", "--no-record"], "rozyn demo: error: window_s: must lie in [1, 3600] s"),
    (["demo", "--speed-kmh", "0", "--no-record"], "rozyn demo: error: speed_kmh: must lie in [1, 400] km/h"),
    (["replay", "bags/samples/iso-a-100kmh", "--window-s", "0.5", "--no-bag"],
     "rozyn replay: error: window_s: must lie in [1, 3600] s"),
])
def test_tool_options_follow_the_nodes_rules(args, words, capsys, tmp_path):
    """The demo and replay check their options with the nodes' own rules: one line, status 1."""
    root = Path(__file__).resolve().parents[1]
    args = [str(root / a) if a.startswith("bags/") else a for a in args] + (
        ["--out", str(tmp_path / "r")] if args[0] == "replay" else [])
    assert main(args) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith(words) and "\n" not in err
