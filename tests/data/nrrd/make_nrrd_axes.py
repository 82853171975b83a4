"""Writes 4-D NRRD test files with one non-spatial axis of size 1 using pynrrd, and adds their
reference geometry to reference.json beside this file.

Files (the 4x3x2 int16 volume of make_nrrd.py, values 5 i - 30 for voxel id i = x + 4 (y + 3 z),
`encoding: raw`, `endian: little`, `dimension: 4`):

  vector-first.nrrd   sizes 1 4 3 2, kinds: vector space space space,
                      space directions: none (..) (..) (..)
  list-last.nrrd      sizes 4 3 2 1, kinds: space space space list,
                      space directions: (..) (..) (..) none

The three space axes have the geometry of oblique-*.nrrd: `space: left-posterior-superior`,
`space origin: (10,-20,30)` (LPS) and space axis k's vector = spacing[k] times column k of
R = Rx(20 deg) @ Rz(30 deg), spacing (0.5, 0.75, 2). pynrrd writes a row of NaN in
`space directions` as `none`.

Each entry in reference.json gives the geometry from the header as pynrrd reads it back (the
space axes only) and SimpleITK's reading, both converted from LPS to RAS (x and y of points and
the first two rows of the direction negated), as make_nrrd.py does. SimpleITK 2.5.7 reads both
files as 3-D images of 1-component vectors (size 4 3 2; ITK moves the non-spatial axis first and
makes it the pixel's components). Index (1,2,1) is the index on the three space axes; the
non-spatial axis has only index 0.

This script loads reference.json and replaces or adds only its own two entries, so the entries
written by make_nrrd.py stay as they are. make_nrrd.py rewrites reference.json from scratch: run
this script after it.

Made with Python 3.11, numpy 2.4.6, pynrrd 1.1.3, SimpleITK 2.5.7
(pip install numpy pynrrd SimpleITK). Run from anywhere: python3 make_nrrd_axes.py
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
NONE_ROW = np.full((1, 3), np.nan)  # pynrrd writes it as `none`


def rot(axis, deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


R = rot("x", 20) @ rot("z", 30)  # columns: the LPS directions of space axes x, y, z
SPACE_ROWS = (R * SPACING).T  # pynrrd takes one ROW per axis: row k = spacing[k] * R[:, k]

# name -> (data in index order F, sizes, kinds, space directions rows, index of the non-spatial axis)
FILES = {
    "vector-first.nrrd": (RAW[None, ...], [1, NX, NY, NZ], ["vector", "space", "space", "space"],
                          np.vstack([NONE_ROW, SPACE_ROWS]), 0),
    "list-last.nrrd": (RAW[..., None], [NX, NY, NZ, 1], ["space", "space", "space", "list"],
                       np.vstack([SPACE_ROWS, NONE_ROW]), 3),
}
ENCODING = "raw"


def write(name):
    data, sizes, kinds, sd, _ = FILES[name]
    header = {
        "type": "int16",
        "dimension": 4,
        "space": "left-posterior-superior",
        "sizes": np.array(sizes),
        "space directions": sd,
        "space origin": ORIGIN_LPS,
        "kinds": kinds,
        "endian": "little",
        "encoding": ENCODING,
    }
    nrrd.write(os.path.join(HERE, name), data, header, index_order="F")


def header_line(name, field):
    text = open(name, "rb").read().split(b"\n\n", 1)[0].decode()
    return next(l for l in text.splitlines() if l.startswith(field + ":"))


def from_header(name):
    """Geometry from the header as pynrrd reads it: the rows of `space directions` that are not
    `none` (NaN) are the space axes, in order; D column k = space row k / its norm."""
    data, hdr = nrrd.read(name, index_order="F")
    sd_all = np.asarray(hdr["space directions"], dtype=float)
    space_axes = [k for k in range(sd_all.shape[0]) if np.all(np.isfinite(sd_all[k]))]
    assert space_axes == [k for k, kind in enumerate(hdr["kinds"]) if kind == "space"]
    sd = sd_all[space_axes]
    spacing = np.linalg.norm(sd, axis=1)
    d_lps = (sd / spacing[:, None]).T
    o_lps = np.asarray(hdr["space origin"], dtype=float)
    p_lps = o_lps + d_lps @ (spacing * np.array(PROBE))
    return data, hdr, space_axes, {
        "reader": "pynrrd %s header, space axes only (LPS converted to RAS)" % nrrd.__version__,
        "space_axes": space_axes,
        "spacing": spacing.tolist(),
        "origin": (FLIP @ o_lps).tolist(),
        "direction": (FLIP @ d_lps).tolist(),
        "point_1_2_1": (FLIP @ p_lps).tolist(),
    }


def from_sitk(name):
    try:
        im = sitk.ReadImage(name)
    except RuntimeError as e:
        return {"reader": "SimpleITK %s" % sitk.Version.VersionString(),
                "error": str(e).strip().splitlines()[-1]}
    assert im.GetDimension() == 3
    ncomp = im.GetNumberOfComponentsPerPixel()
    # (z, y, x[, components]); SimpleITK drops the component axis when there is one component.
    v = sitk.GetArrayFromImage(im).reshape(im.GetSize()[::-1] + (ncomp,))
    assert ncomp == 1 and np.array_equal(v[..., 0].transpose(2, 1, 0), RAW)  # every voxel in place
    return {
        "reader": "SimpleITK %s (ITK LPS converted to RAS)" % sitk.Version.VersionString(),
        "size": list(im.GetSize()),
        "components_per_pixel": ncomp,
        "spacing": list(im.GetSpacing()),
        "origin": (FLIP @ np.array(im.GetOrigin())).tolist(),
        "direction": (FLIP @ np.array(im.GetDirection()).reshape(3, 3)).tolist(),
        "point_1_2_1": (FLIP @ np.array(im.TransformIndexToPhysicalPoint(PROBE))).tolist(),
        "itk_lps_point_1_2_1": list(im.TransformIndexToPhysicalPoint(PROBE)),
        "pixel_type": im.GetPixelIDTypeAsString(),
        "values": {"sum": int(v.sum()), "min": int(v.min()), "max": int(v.max())},
        "value_at_1_2_1": int(v[PROBE[2], PROBE[1], PROBE[0], 0]),
    }


def dump_json(obj, path):
    text = json.dumps(obj, indent=1)
    text = re.sub(r"\[\s*([-+0-9.eE,\s]+?)\s*\]", lambda m: "[" + ", ".join(m.group(1).split()).replace(",,", ",") + "]", text)
    with open(path, "w") as f:
        f.write(text + "\n")


def main():
    os.chdir(HERE)
    with open("reference.json") as f:
        ref = json.load(f)
    for name in FILES:
        write(name)
        data, hdr, space_axes, head = from_header(name)
        itk = from_sitk(name)
        expect, sizes, kinds, _, other = FILES[name]
        assert np.array_equal(data, expect)
        assert space_axes == [k for k in range(4) if k != other]
        if "error" not in itk:
            assert np.allclose(head["point_1_2_1"], itk["point_1_2_1"])
            assert itk["value_at_1_2_1"] == int(RAW[PROBE])
        ref["files"][name] = {
            "bytes": os.path.getsize(name),
            "encoding": ENCODING,
            "written_by": "pynrrd %s (make_nrrd_axes.py)" % nrrd.__version__,
            "size": [NX, NY, NZ],
            "nrrd_dimension": 4,
            "nrrd_sizes": sizes,
            "kinds": kinds,
            "non_spatial_axis": other,
            "space_directions_line": header_line(name, "space directions"),
            "stored_type": "int16 (little-endian where binary)",
            "values": {"sum": int(RAW.sum()), "min": int(RAW.min()), "max": int(RAW.max())},
            "value_at_1_2_1": int(RAW[PROBE]),
            "geometry": {"simpleitk": itk, "header": head},
        }
    dump_json(ref, "reference.json")
    for name in FILES:
        g = ref["files"][name]["geometry"]
        print(name, ref["files"][name]["bytes"], "bytes; RAS point (1,2,1):", g["header"]["point_1_2_1"],
              "; SimpleITK:", g["simpleitk"].get("error", g["simpleitk"].get("point_1_2_1")))


if __name__ == "__main__":
    main()
