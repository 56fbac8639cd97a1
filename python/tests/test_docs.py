"""docs/python.md and docs/planner.md run as written: their sh and python blocks in order, in a
scratch directory (a block after a "not run" comment is skipped); examples/python/ runs on the
same recording."""

import os
import re
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BIN = os.environ.get("DENSEMAP_BIN", "")


def blocks(path):
    text = open(path).read()
    for match in re.finditer(r"(<!-- not run[^>]*-->\n)?```(sh|python)\n(.*?)```", text, re.S):
        if not match.group(1):
            yield match.group(2), match.group(3)


@pytest.fixture()
def scratch(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("PATH", BIN + os.pathsep + os.environ.get("PATH", ""))
    return tmp_path


def test_python_md_runs(scratch):
    namespace = {}
    ran = {"sh": 0, "python": 0}
    for language, code in blocks(os.path.join(ROOT, "docs", "python.md")):
        if language == "sh":
            subprocess.run(code, shell=True, check=True, stdout=subprocess.DEVNULL,
                           stderr=subprocess.DEVNULL)
        else:
            exec(compile(code, "docs/python.md", "exec"), namespace)  # noqa: S102
        ran[language] += 1
    assert ran["sh"] >= 1 and ran["python"] >= 6
    assert (scratch / "top_view.png").stat().st_size > 1000
    assert namespace["mapper"].known_cells > 0 and namespace["hit"][0]


def test_map_recording_example(scratch):
    subprocess.run([os.path.join(BIN, "densemap-sim"), "--out", "drive", "--scene", "indoor",
                    "--sensor", "vlp16", "--scans", "3", "--gt-resolution", "0"],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    env = dict(os.environ, PYTHONPATH=os.environ.get("DENSEMAP_PYTHON_DIR", ""))
    out = subprocess.run([sys.executable, os.path.join(ROOT, "examples", "python",
                                                       "map_recording.py"),
                          "drive", "--out", "drive.bt", "--top-view", "top.png"],
                         check=True, capture_output=True, text=True, env=env).stdout
    assert "3 scans" in out and (scratch / "drive.bt").stat().st_size > 0
    assert (scratch / "top.png").exists()
    bad = subprocess.run([sys.executable, os.path.join(ROOT, "examples", "python",
                                                       "map_recording.py"), "no-such-thing"],
                         capture_output=True, text=True, env=env)
    assert bad.returncode != 0 and "map_recording:" in bad.stderr


def test_planner_md_runs(scratch):
    namespace = {}
    ran = 0
    for language, code in blocks(os.path.join(ROOT, "docs", "planner.md")):
        assert language == "python"
        exec(compile(code, "docs/planner.md", "exec"), namespace)  # noqa: S102
        ran += 1
    assert ran >= 3
    distances = namespace["distances"]
    assert abs(distances[0] - 0.5) < 1e-6 and distances[1] == 0 and distances[2] == 1.0
    assert abs(namespace["answer"]["occupied"]["arc_length"] - 1.2) < 1e-4
