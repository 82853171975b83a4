"""What the tests share: the command-line binary they compare against, the shared data, and
helpers that run it and read what it writes.

``SPLATSCENE_BIN`` names the binary (default: the repository's ``target/release/splatscene``);
``SPLATSCENE_DATA`` the shared data (default: ``../shared/data`` beside the repository).
"""

import json
import os
import pathlib
import subprocess

import numpy as np
import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]


def binary() -> pathlib.Path:
    path = pathlib.Path(os.environ.get("SPLATSCENE_BIN", REPO / "target" / "release" / "splatscene"))
    if not path.exists():
        pytest.fail(f"{path}: no splatscene binary; build it with cargo build --release or set SPLATSCENE_BIN")
    return path


def data_dir() -> pathlib.Path:
    return pathlib.Path(os.environ.get("SPLATSCENE_DATA", REPO.parent / "shared" / "data"))


def data_file(relative: str) -> pathlib.Path:
    path = data_dir() / relative
    if not path.exists():
        pytest.fail(f"{path}: missing; set SPLATSCENE_DATA to the shared data folder")
    return path


def cli(*args, cwd=None) -> subprocess.CompletedProcess:
    """Runs the command line; fails the test with its stderr when it fails."""
    env = dict(os.environ, NODEVICE_SELECT="1")
    done = subprocess.run([str(binary()), *map(str, args)], capture_output=True, cwd=cwd, env=env)
    if done.returncode != 0:
        pytest.fail(f"splatscene {' '.join(map(str, args))} failed:\n{done.stderr.decode(errors='replace')}")
    return done


def cli_json(*args):
    return json.loads(cli(*args).stdout)


def read_png(path) -> np.ndarray:
    """A PNG file as an array: RGBA8 as (h, w, 4) uint8, 16-bit grey as (h, w) uint16."""
    from PIL import Image as PilImage

    with PilImage.open(path) as im:
        if im.mode in ("I;16", "I;16B", "I"):
            return np.array(im, dtype=np.uint16)
        return np.array(im.convert("RGBA"))


def cli_render(scene_or_volume, out: pathlib.Path, *args) -> np.ndarray:
    cli("render", scene_or_volume, "--out", out, *args)
    return read_png(out)
