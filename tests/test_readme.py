"""Every code block of README.md runs.

``python`` blocks are executed in order, in one namespace; ``bash``/``sh`` blocks command by command, in the same
folder, which holds the user's files the README names (``a.obj``, ``b.obj``, ``g.obj``, the same scene as Y-up
centimetre ``.glb``, ``skirt.obj`` on the default Anny body, a ``bodies/`` folder), made here from the fixture
dataset. ``garsim ... --help`` runs through a subprocess (the real entry point); the other ``garsim`` commands run
in this process through ``garsim.cli.main`` (same code, without paying torch's import and the model load per line).

Nothing is skipped silently: a whole block is skipped only behind a ``<!-- not-tested: reason -->`` line just
above it in the README, and single commands only when listed in ``SKIPPED_COMMANDS`` below, with the reason.
Any other command fails the test.
"""

from __future__ import annotations

import json
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
FIXTURE = Path(__file__).resolve().parent / "fixtures" / "dataset_v2"
RUN_LANGUAGES = {"python", "bash", "sh", "shell"}
NOT_TESTED = re.compile(r"^<!--\s*not-tested:\s*(\S.*?)\s*-->\s*$")

SKIPPED_COMMANDS: dict[str, str] = {
    "garsim demo": "drapes every family on two bodies and renders an animation (~1 min); "
    "tests/test_cli.py::test_demo runs it on tiny settings",
    "garsim view": "serves until interrupted; tests/test_view.py starts the server and screenshots it",
    "garsim data generate": "simulates a dataset with Newton (hours)",
    "garsim data info": "reads the dataset the line above generates; tests/test_cli.py runs it on a small one",
}
"""Command prefix -> why the README test does not run it."""


@dataclass
class Block:
    language: str
    code: str
    line: int  # of the opening fence, 1-based
    not_tested: str | None  # the reason of a <!-- not-tested: ... --> marker just above


def readme_blocks(text: str | None = None) -> list[Block]:
    """The fenced code blocks of the README, in order."""
    lines = (README.read_text(encoding="utf-8") if text is None else text).splitlines()
    blocks, i = [], 0
    while i < len(lines):
        m = re.match(r"^```(\w*)\s*$", lines[i])
        if not m:
            i += 1
            continue
        start = i
        i += 1
        body = []
        while i < len(lines) and not lines[i].startswith("```"):
            body.append(lines[i])
            i += 1
        above = start - 1
        while above >= 0 and not lines[above].strip():
            above -= 1
        marker = NOT_TESTED.match(lines[above].strip()) if above >= 0 else None
        blocks.append(Block(m.group(1).lower(), "\n".join(body) + "\n", start + 1, marker.group(1) if marker else None))
        i += 1
    return blocks


def shell_commands(code: str) -> list[list[str]]:
    """The commands of a shell block (comments dropped, backslash continuations joined) as argument lists."""
    return [argv for line in code.replace("\\\n", " ").splitlines() if (argv := shlex.split(line, comments=True))]


def skip_reason(argv: list[str]) -> str | None:
    command = " ".join(argv)
    for prefix, reason in SKIPPED_COMMANDS.items():
        if command == prefix or command.startswith(prefix + " "):
            return reason
    return None


def test_readme_blocks_are_accounted_for():
    """Every runnable block is run or marked with a reason; every listed skip is still used; no unknown command."""
    blocks = [b for b in readme_blocks() if b.language in RUN_LANGUAGES]
    assert sum(b.language == "python" for b in blocks) >= 2 and blocks
    used = set()
    for block in blocks:
        if block.not_tested is not None or block.language == "python":
            continue
        for argv in shell_commands(block.code):
            if skip_reason(argv) is not None:
                used.add(next(p for p in SKIPPED_COMMANDS if " ".join(argv).startswith(p)))
            else:
                assert argv[0] == "garsim", (
                    f"README.md:{block.line}: cannot run {' '.join(argv)!r} (list it with a reason)"
                )
    assert used == set(SKIPPED_COMMANDS), f"stale entries: {set(SKIPPED_COMMANDS) - used}"


def test_parser_and_markers():
    text = (
        "a\n<!-- not-tested: too slow -->\n\n```bash\nmake x  # y\ngarsim a \\\n  --b c\n```\n```python\nx = 1\n```\n"
    )
    blocks = readme_blocks(text)
    assert [(b.language, b.not_tested, b.line) for b in blocks] == [("bash", "too slow", 4), ("python", None, 9)]
    assert shell_commands(blocks[0].code) == [["make", "x"], ["garsim", "a", "--b", "c"]]


@pytest.fixture(scope="module")
def user_files(tmp_path_factory, anny_body):
    """The files the README's examples name, from the fixture dataset (a skirt on an Anny body) and Anny."""
    from garsim.garments.templates import make_garment
    from garsim.geometry.io import save_mesh

    folder = tmp_path_factory.mktemp("readme")
    with np.load(FIXTURE / "sequences" / "test-00040.npz", allow_pickle=False) as z:
        canonical, target = z["body_canonical"], z["body_targets"][0]
        garment, garment_faces = z["low/template"], z["low/faces"]
    body_faces = np.load(next((FIXTURE / "body_faces").glob("*.npy")))
    scene = {"a": (canonical, body_faces), "b": (target, body_faces), "g": (garment, garment_faces)}
    for name, (v, f) in scene.items():
        save_mesh(folder / f"{name}.obj", v, f)
        save_mesh(folder / f"{name}.glb", v * 100.0, f, y_up=True)  # a Blender/glTF scene: Y up, centimetres
    (folder / "bodies").mkdir()
    for k, t in enumerate((0.5, 1.0)):
        save_mesh(folder / "bodies" / f"{k:03d}.obj", canonical + t * (target - canonical), body_faces)
    skirt = make_garment("skirt", anny_body, target_vertices=300)
    save_mesh(folder / "skirt.obj", skirt.vertices, skirt.faces)
    save_mesh(folder / "skirt.glb", skirt.vertices, skirt.faces, y_up=True)
    _skinned_avatar(folder / "avatar.glb", anny_body)
    keyframes = [{"shoulder_elevation_L": -60, "shoulder_elevation_R": -60}, {"hip_flexion_L": 25}]
    (folder / "keyframes.json").write_text(json.dumps(keyframes))
    return folder


def _skinned_avatar(path: Path, body) -> Path:
    """The default Anny body as a user's avatar: a Y-up GLB skinned to its bones, the T-pose stored, a walk animated."""
    from gltf_builder import skinned_body

    from garsim.bodies.poses import motion, pose_bodies_rigged
    from garsim.geometry.io import z_up_to_y_up

    c = np.eye(4)
    c[:3, :3] = z_up_to_y_up(np.eye(3)).T  # column vectors: p' = c p
    turn = lambda t: c @ t @ c.T  # noqa: E731 - the same motion in Y-up axes
    walk = pose_bodies_rigged(body, motion("walk", 3))[1]
    tpose = pose_bodies_rigged(body, [body.t_pose()])[1][0]
    rig = (body.skin_weights, body.skin_indices, turn(tpose), turn(walk))
    return skinned_body(path, z_up_to_y_up(body.rest_vertices), body.faces, *rig)


def _outputs(argv: list[str]) -> list[str]:
    return [argv[i + 1] for i, a in enumerate(argv[:-1]) if a in ("--out", "--png")]


def test_readme_code_runs(user_files, monkeypatch, capsys):
    import torch

    from garsim.cli import _THREAD_VARS, main

    monkeypatch.chdir(user_files)
    for var in _THREAD_VARS:  # main() pins them for drape/animate: restore them after the test
        monkeypatch.setenv(var, "1")
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # as `garsim drape` in its own process: no thread pool to spin on shared cores
    try:
        _run_readme(main, capsys)
    finally:
        torch.set_num_threads(threads)


def _run_readme(main, capsys) -> None:
    namespace: dict = {"__name__": "__readme__"}
    ran = []
    for block in readme_blocks():
        if block.language not in RUN_LANGUAGES or block.not_tested is not None:
            continue
        if block.language == "python":
            exec(compile(block.code, f"README.md:{block.line}", "exec"), namespace)
            ran.append(f"python block at line {block.line}")
            continue
        for argv in shell_commands(block.code):
            if skip_reason(argv) is not None:
                continue
            where = f"README.md:{block.line}: {' '.join(argv)}"
            if "--help" in argv or "-h" in argv:
                r = subprocess.run(
                    [sys.executable, "-m", "garsim.cli", *argv[1:]], capture_output=True, text=True, timeout=120
                )
                assert r.returncode == 0 and "Example:" in r.stdout, f"{where}\n{r.stderr}"
            else:
                rc = main(argv[1:])
                captured = capsys.readouterr()
                assert rc == 0, f"{where}\n{captured.err}"
                for out in _outputs(argv):  # a file, or a folder of them (batch drapes)
                    files = sorted(Path(out).iterdir()) if Path(out).is_dir() else [Path(out)]
                    assert files, f"{where}: {out} is empty"
                    for f in files:
                        assert f.is_file() and f.stat().st_size > 0, f"{where}: no {f}"
                        assert str(f) in captured.out, f"{where}: {f} not printed"
            ran.append(" ".join(argv))
    assert np.isfinite(namespace["verts"]).all()
    assert any(r.startswith("garsim drape") for r in ran) and any(r.startswith("garsim animate") for r in ran)
