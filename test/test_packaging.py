"""The package builds with colcon as a ROS 2 user builds it (ament_python layout)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
COLCON = Path(sys.executable).parent / "colcon"
SOURCES = ("package.xml", "setup.py", "setup.cfg", "resource", "rozyn_estimator", "sim_node", "config",
           "launch")
EXECUTABLES = ("estimator_node", "sim_node", "rozyn", "bag_recorder")


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    if not COLCON.exists():
        pytest.skip("colcon is not installed in this environment")
    ws = tmp_path_factory.mktemp("ws")
    pkg = ws / "src" / "rozyn_estimator"
    pkg.mkdir(parents=True)
    for name in SOURCES:
        src = ROOT / name
        if src.is_dir():
            shutil.copytree(src, pkg / name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy2(src, pkg / name)
    return ws


@pytest.mark.parametrize("symlink", [False, True], ids=["install", "symlink-install"])
def test_colcon_build_installs_the_ros_layout(workspace, symlink):
    for d in ("build", "install", "log"):
        shutil.rmtree(workspace / d, ignore_errors=True)
    cmd = [str(COLCON), "build", "--base-paths", "src"] + (["--symlink-install"] if symlink else [])
    done = subprocess.run(cmd, cwd=workspace, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    prefix = workspace / "install" / "rozyn_estimator"
    for exe in EXECUTABLES:
        path = prefix / "lib" / "rozyn_estimator" / exe
        assert path.is_file() and os.access(path, os.X_OK), exe
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / "rozyn_estimator").is_file()
    assert (prefix / "share" / "rozyn_estimator" / "package.xml").is_file()
    assert (prefix / "share" / "rozyn_estimator" / "config" / "vehicle.yaml").exists()
    for launch_file in ("sim_estimator.launch.py", "estimator.launch.py"):  # where ros2 launch looks
        assert (prefix / "share" / "rozyn_estimator" / "launch" / launch_file).exists()
    site = next(prefix.glob("lib/python3*/site-packages"))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]))
    run = subprocess.run([sys.executable, str(prefix / "lib" / "rozyn_estimator" / "rozyn"), "--help"],
                         capture_output=True, text=True, env=env, cwd=workspace)
    assert run.returncode == 0 and "trial" in run.stdout
