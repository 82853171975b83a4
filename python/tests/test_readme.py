"""The README's Python example runs as written and draws the picture of the command it shows
beside it."""

import re
import shlex
import shutil
import struct
import subprocess

import numpy as np

import splatscene
from conftest import REPO, binary, data_file, read_png
from test_ecosystem import close_pictures


def readme_blocks():
    text = (REPO / "README.md").read_text()
    section = text[text.index("## Python\n"):]
    section = section[: section.index("\n## ", 1)]
    python = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    # The command's block is marked `shell`, not `sh`: tests/readme.rs runs every `sh` block
    # in a folder without ct.nii.gz and stem.stl; this test runs it beside them.
    command = [m for m in re.findall(r"```shell\n(.*?)```", section, re.S) if m.startswith("splatscene render")][0]
    return python, command


def write_stl(path, mesh):
    """A binary STL of a mesh's triangles (normals left zero, as readers recompute them)."""
    v, f = mesh.vertices, mesh.faces
    with open(path, "wb") as out:
        out.write(b"\0" * 80 + struct.pack("<I", len(f)))
        for a, b, c in f:
            out.write(struct.pack("<12fH", 0, 0, 0, *v[a], *v[b], *v[c], 0))


def test_the_readme_example_draws_what_its_command_draws(tmp_path, monkeypatch):
    python, command = readme_blocks()
    shutil.copy(data_file("volumes/totalseg_ct/aorta_ct_cropped.nii.gz"), tmp_path / "ct.nii.gz")
    write_stl(tmp_path / "stem.stl", splatscene.Mesh.from_file("builtin:prosthesis"))
    monkeypatch.chdir(tmp_path)
    exec(compile(python, "README.md", "exec"), {})
    mine = read_png(tmp_path / "plan.png")
    (tmp_path / "plan.png").rename(tmp_path / "from-python.png")
    args = shlex.split(command.replace("\\\n", " "))
    assert args[0] == "splatscene"
    subprocess.run([str(binary()), *args[1:]], cwd=tmp_path, check=True, capture_output=True)
    theirs = read_png(tmp_path / "plan.png")
    assert mine.shape == theirs.shape == (480, 640, 4)
    close_pictures(mine, theirs)
    # The stem shows: the picture differs from the CT alone where it stands.
    alone = splatscene.Scene([splatscene.load_volume(tmp_path / "ct.nii.gz")], transfer="ct-bone").render(
        size=(640, 480), view="anterior", annotate=True)
    assert (np.abs(alone.astype(int) - theirs).max(axis=2) > 40).mean() > 0.005
