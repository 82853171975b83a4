"""Writes the NRRD test files in this folder with pynrrd and records reference geometry.

Files (4x3x2 int16, values 5 i - 30 for voxel id i = x + 4 (y + 3 z)):

  oblique-bzip2.nrrd   `encoding: bzip2` (the main target)
  oblique-ascii.nrrd   the same with `encoding: ascii`

Both have `space: left-posterior-superior`, `space origin: (10,-20,30)` (LPS) and oblique,
non-symmetric, non-square `space directions`: axis k's vector is spacing[k] times column k of
R = Rx(20 deg) @ Rz(30 deg), spacing (0.5, 0.75, 2). This is the same physical (LPS) geometry
as ../metaimage/oblique.mha.

reference.json records, per file, the geometry computed from the header as pynrrd reads it back
and SimpleITK's reading, both converted from LPS to RAS (x and y of points and the first two rows
of the direction negated). SimpleITK 2.5.7 cannot read the bzip2 file (ITK's NrrdIO is built
without bzip2: "bzip2 encoding not available in NrrdIO"); it reads the ascii file, whose header
is otherwise identical, and agrees with the header figures there, which cross-checks them.

Made with Python 3.11, numpy 2.4.6, pynrrd 1.1.3, SimpleITK 2.5.7
(pip install numpy pynrrd SimpleITK). Run from anywhere: python3 make_nrrd.py
"""
import json
import math
import os
import re

import nrrd
import numpy as np
import SimpleITK as sitk

HERE = os.path.dirname(os.path.abspath(__file__))
NX, NY, NZ = 4, 3, 2
SPACING = np.array([0.5, 0.75, 2.0])
ORIGIN_LPS = np.array([10.0, -20.0, 30.0])
PROBE = (1, 2, 1)
RAW = (np.arange(NX * NY * NZ, dtype=np.int16) * 5 - 30).reshape((NZ, NY, NX)).transpose(2, 1, 0).copy()
FLIP = np.diag([-1.0, -1.0, 1.0])  # LPS <-> RAS


def rot(axis, deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


R = rot("x", 20) @ rot("z", 30)  # columns: the LPS directions of index axes x, y, z


def write(name, encoding):
    header = {
        "type": "int16",
        "dimension": 3,
        "space": "left-posterior-superior",
        "sizes": np.array([NX, NY, NZ]),
        # pynrrd takes one ROW per index axis: row k = spacing[k] * R[:, k].
        "space directions": (R * SPACING).T,
        "space origin": ORIGIN_LPS,
        "kinds": ["domain", "domain", "domain"],
        "endian": "little",
        "encoding": encoding,
    }
    nrrd.write(os.path.join(HERE, name), RAW, header, index_order="F")


def from_header(name):
    """Geometry from the header as pynrrd reads it: D column k = row k of space directions / its norm."""
    data, hdr = nrrd.read(name, index_order="F")
    sd = np.asarray(hdr["space directions"], dtype=float)  # rows = axis vectors, LPS
    spacing = np.linalg.norm(sd, axis=1)
    d_lps = (sd / spacing[:, None]).T
    o_lps = np.asarray(hdr["space origin"], dtype=float)
    p_lps = o_lps + d_lps @ (spacing * np.array(PROBE))
    return data, hdr, {
        "reader": "pynrrd %s header (LPS converted to RAS)" % nrrd.__version__,
        "spacing": spacing.tolist(),
        "origin": (FLIP @ o_lps).tolist(),
        "direction": (FLIP @ d_lps).tolist(),
        "point_1_2_1": (FLIP @ p_lps).tolist(),
    }


def from_sitk(name):
    try:
        im = sitk.ReadImage(name)
    except RuntimeError as e:
        # ITK's NrrdIO is built without bzip2: keep its last message line.
        return {"reader": "SimpleITK %s" % sitk.Version.VersionString(),
                "error": str(e).strip().splitlines()[-1]}
    v = sitk.GetArrayFromImage(im)
    return {
        "reader": "SimpleITK %s (ITK LPS converted to RAS)" % sitk.Version.VersionString(),
        "spacing": list(im.GetSpacing()),
        "origin": (FLIP @ np.array(im.GetOrigin())).tolist(),
        "direction": (FLIP @ np.array(im.GetDirection()).reshape(3, 3)).tolist(),
        "point_1_2_1": (FLIP @ np.array(im.TransformIndexToPhysicalPoint(PROBE))).tolist(),
        "itk_lps_point_1_2_1": list(im.TransformIndexToPhysicalPoint(PROBE)),
        "pixel_type": im.GetPixelIDTypeAsString(),
        "values": {"sum": int(v.sum()), "min": int(v.min()), "max": int(v.max())},
        "value_at_1_2_1": int(v[PROBE[2], PROBE[1], PROBE[0]]),
    }


def dump_json(obj, path):
    text = json.dumps(obj, indent=1)
    text = re.sub(r"\[\s*([-+0-9.eE,\s]+?)\s*\]", lambda m: "[" + ", ".join(m.group(1).split()).replace(",,", ",") + "]", text)
    with open(path, "w") as f:
        f.write(text + "\n")


def main():
    os.chdir(HERE)
    files = {}
    for name, enc in (("oblique-bzip2.nrrd", "bzip2"), ("oblique-ascii.nrrd", "ascii")):
        write(name, enc)
        data, hdr, head = from_header(name)
        itk = from_sitk(name)
        assert np.array_equal(data, RAW)
        if "error" not in itk:
            assert np.allclose(head["point_1_2_1"], itk["point_1_2_1"])
        files[name] = {
            "bytes": os.path.getsize(name),
            "encoding": enc,
            "size": [NX, NY, NZ],
            "stored_type": "int16 (little-endian where binary)",
            "values": {"sum": int(RAW.sum()), "min": int(RAW.min()), "max": int(RAW.max())},
            "value_at_1_2_1": int(RAW[PROBE]),
            "geometry": {"simpleitk": itk, "header": head},
        }
    ref = {
        "convention": "dims [nx, ny, nz], x fastest; world point of index (i,j,k) = origin + D * "
                      "(spacing * (i,j,k)); direction rows are the rows of D; all coordinates RAS "
                      "(the files are LPS: x and y negated)",
        "written_by": "pynrrd %s (make_nrrd.py)" % nrrd.__version__,
        "files": files,
    }
    dump_json(ref, "reference.json")
    for name, d in files.items():
        g = d["geometry"]
        print(name, d["bytes"], "bytes; RAS point (1,2,1):", g["header"]["point_1_2_1"],
              "; SimpleITK:", g["simpleitk"].get("error", g["simpleitk"].get("point_1_2_1")))


if __name__ == "__main__":
    main()
