"""A study's output directory: its manifest (``study.json``) and its state.

:func:`prepare_dir` makes a directory ready for a new, replaced (``--force``) or resumed
(``--resume``) study and returns the trials already done there; it refuses to mix two
studies (:func:`check_same_study` names the settings that differ).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.tools.study.results import TrialRow, scan_results, write_results
from rozyn_estimator.tools.study.settings import (
    FIGURES,
    MANIFEST,
    RESULTS,
    SUMMARY_CSV,
    SUMMARY_MD,
    StudySettings,
)

MANIFEST_VERSION = 1


def prepare_dir(out_dir: Path, settings: StudySettings, resume: bool, force: bool) -> list[TrialRow]:
    """Make ``out_dir`` ready for ``settings``; return the trials already done there.

    Raises:
        ConfigError: the directory holds another study, or a study and neither ``resume``
            nor ``force`` was asked for.
    """
    if resume and force:
        raise ConfigError("--resume and --force exclude each other")
    manifest = out_dir / MANIFEST
    results = out_dir / RESULTS
    exists = manifest.exists() or results.exists()
    if exists and force:
        remove_outputs(out_dir)
    elif exists and not resume:
        raise ConfigError(f"{out_dir} already holds a study; continue it with --resume, start it over "
                          f"with --force, or choose another --out")
    elif exists:
        if not manifest.exists():
            raise ConfigError(f"{out_dir}: {RESULTS} without {MANIFEST}: cannot check its settings; "
                              f"use --force to start over")
        check_same_study(load_manifest(out_dir), settings, out_dir)
        if results.exists():
            rows, clean = scan_results(results, settings.car)
            wanted = set(settings.cells())
            kept = [r for r in rows if r.cell in wanted and r.trial < settings.trials]
            if not clean or len(kept) != len(rows):
                write_results(results, kept, settings.car)
            return kept
    out_dir.mkdir(parents=True, exist_ok=True)
    return []


def remove_outputs(out_dir: Path) -> None:
    """Delete the files a study writes (and nothing else) from ``out_dir``."""
    for name in (MANIFEST, RESULTS, SUMMARY_CSV, SUMMARY_MD, RESULTS + ".tmp"):
        (out_dir / name).unlink(missing_ok=True)
    figures = out_dir / FIGURES
    if figures.is_dir():
        for png in figures.glob("*.png"):
            png.unlink()


def new_manifest(settings: StudySettings) -> dict[str, Any]:
    """The manifest of a study that has not run yet."""
    return {"version": MANIFEST_VERSION, "tool": "rozyn study", "settings": settings.to_dict(), "runs": []}


def load_manifest(out_dir: Path) -> dict[str, Any]:
    path = out_dir / MANIFEST
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f"{out_dir}: no {MANIFEST}: not a study directory") from None
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{path}: cannot read: {exc}") from None
    if not isinstance(data, dict) or data.get("version") != MANIFEST_VERSION or "settings" not in data:
        raise ConfigError(f"{path}: not a study manifest of version {MANIFEST_VERSION}")
    return data


def write_manifest(out_dir: Path, data: dict[str, Any]) -> None:
    tmp = out_dir / (MANIFEST + ".tmp")
    tmp.write_text(json.dumps(data, indent=2) + "\n")
    os.replace(tmp, out_dir / MANIFEST)


def check_model(stored: str, asked: str, out_dir: Path) -> None:
    """Refuse to continue (or plot) a study of one vehicle model as the other's."""
    if stored != asked:
        raise ConfigError(f"{out_dir} holds a study of the {stored} car (--model {stored}), not of the "
                          f"{asked} car; leave --model out to continue it, use another --out, or --force to "
                          "start over")


def check_same_study(manifest: dict[str, Any], settings: StudySettings, out_dir: Path) -> None:
    """Refuse to resume a study with other settings (naming what differs)."""
    old = manifest["settings"]
    check_model(old.get("model", "half"), settings.model, out_dir)
    new = json.loads(json.dumps(settings.to_dict()))
    differ = sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))
    if differ:
        details = "; ".join(f"{k}: {_short(old.get(k))} there, {_short(new.get(k))} asked" for k in differ)
        raise ConfigError(f"{out_dir} holds a different study ({details}); use another --out, "
                          f"or --force to start over")


def _short(value: Any) -> str:
    text = json.dumps(value)
    return text if len(text) <= 60 else text[:57] + "..."
