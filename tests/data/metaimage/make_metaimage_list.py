"""Writes hand-made MetaImage headers whose forms SimpleITK does not write, and records what
SimpleITK reads from them (and from the files make_metaimage.py writes).

Volume: 4x3x2 MET_SHORT little-endian, values 5 i - 30 for voxel id i = x + 4 (y + 3 z),
ElementSpacing 0.5 0.75 2, Offset 10 -20 30 (ITK's LPS), and the oblique, non-symmetric
direction R = Rx(20 deg) @ Rz(30 deg) written as SimpleITK writes it in oblique.mhd:
TransformMatrix lists R column by column (R[0][0] R[1][0] R[2][0] R[0][1] ...).

Files:
  list.mhd + list-z0.raw, list-z1.raw      ElementDataFile = LIST, then one file name per line,
                                           one 2-D slice (12 voxels, 24 bytes) per file
  pattern.mhd + slice001.raw, slice002.raw ElementDataFile = slice%03d.raw 1 2 1
                                           (printf pattern, first 1, last 2, step 1)
  orientation-lpi.mhd + orientation.raw    AnatomicalOrientation = LPI and no TransformMatrix
  orientation-lpi-oblique.mhd              the same data file, AnatomicalOrientation = LPI and the
                                           oblique TransformMatrix (which contradicts LPI)

SimpleITK cannot write the LIST or pattern forms, and writes AnatomicalOrientation itself
(derived from the direction: RAI for oblique.mhd), so these headers are written by hand.
SimpleITK ignores AnatomicalOrientation when reading: orientation-lpi.mhd reads with the identity
direction, orientation-lpi-oblique.mhd with the TransformMatrix.

reference.json gives SimpleITK's reading converted from ITK's LPS to RAS (x and y of points and
the first two rows of the direction negated), and for comparison VTK's vtkMetaImageReader, which
takes TransformMatrix row by row, i.e. the TRANSPOSE of ITK's direction (VTK coordinates, no
conversion).

Made with Python 3.11, numpy 2.4.6, SimpleITK 2.5.7, VTK 9.7.2 (pip install numpy SimpleITK vtk).
Run from anywhere: python3 make_metaimage_list.py
"""
import json
import math
import os
import re

import numpy as np
import SimpleITK as sitk
import vtk
from vtk.util import numpy_support

HERE = os.path.dirname(os.path.abspath(__file__))
NX, NY, NZ = 4, 3, 2
PROBE = (1, 2, 1)
FLIP = np.diag([-1.0, -1.0, 1.0])  # LPS <-> RAS
VALUES = (np.arange(NX * NY * NZ, dtype="<i2") * 5 - 30).astype("<i2")  # x fastest


def rot(axis, deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


R = rot("x", 20) @ rot("z", 30)
COMMON = [
    "ObjectType = Image",
    "NDims = 3",
    "BinaryData = True",
    "BinaryDataByteOrderMSB = False",
    "CompressedData = False",
]
GEOMETRY = [
    "Offset = 10 -20 30",
    "ElementSpacing = 0.5 0.75 2",
    "DimSize = 4 3 2",
    "ElementType = MET_SHORT",
]
TRANSFORM = "TransformMatrix = " + " ".join(repr(float(x)) for x in R.T.ravel())  # column by column


def header(lines):
    return "\n".join(lines) + "\n"


def write_all():
    slice_bytes = NX * NY * 2
    raw = VALUES.tobytes()
    # LIST form
    for z in range(NZ):
        with open("list-z%d.raw" % z, "wb") as f:
            f.write(raw[z * slice_bytes:(z + 1) * slice_bytes])
    with open("list.mhd", "w") as f:
        f.write(header(COMMON + [TRANSFORM] + GEOMETRY + ["ElementDataFile = LIST", "list-z0.raw", "list-z1.raw"]))
    # pattern form: slice001.raw, slice002.raw
    for k in range(1, NZ + 1):
        with open("slice%03d.raw" % k, "wb") as f:
            f.write(raw[(k - 1) * slice_bytes:k * slice_bytes])
    with open("pattern.mhd", "w") as f:
        f.write(header(COMMON + [TRANSFORM] + GEOMETRY + ["ElementDataFile = slice%03d.raw 1 2 1"]))
    # AnatomicalOrientation, without and with a TransformMatrix
    with open("orientation.raw", "wb") as f:
        f.write(raw)
    with open("orientation-lpi.mhd", "w") as f:
        f.write(header(COMMON + ["AnatomicalOrientation = LPI"] + GEOMETRY + ["ElementDataFile = orientation.raw"]))
    with open("orientation-lpi-oblique.mhd", "w") as f:
        f.write(header(COMMON + [TRANSFORM, "AnatomicalOrientation = LPI"] + GEOMETRY
                       + ["ElementDataFile = orientation.raw"]))


def from_sitk(name):
    im = sitk.ReadImage(name)
    v = sitk.GetArrayFromImage(im)
    d = np.array(im.GetDirection()).reshape(3, 3)
    return {
        "reader": "SimpleITK %s (ITK LPS converted to RAS)" % sitk.Version.VersionString(),
        "size": list(im.GetSize()),
        "spacing": list(im.GetSpacing()),
        "origin": (FLIP @ np.array(im.GetOrigin())).tolist(),
        "direction": (FLIP @ d).tolist(),
        "point_1_2_1": (FLIP @ np.array(im.TransformIndexToPhysicalPoint(PROBE))).tolist(),
        "itk_lps": {"origin": list(im.GetOrigin()), "direction": d.tolist(),
                    "point_1_2_1": list(im.TransformIndexToPhysicalPoint(PROBE))},
        "pixel_type": im.GetPixelIDTypeAsString(),
        "values": {"sum": int(v.sum()), "min": int(v.min()), "max": int(v.max())},
        "value_at_1_2_1": int(v[PROBE[2], PROBE[1], PROBE[0]]),
    }


def from_vtk(name):
    r = vtk.vtkMetaImageReader()
    r.SetFileName(name)
    r.Update()
    img = r.GetOutput()
    m = img.GetDirectionMatrix()
    p = [0.0, 0.0, 0.0]
    img.TransformIndexToPhysicalPoint(*PROBE, p)
    v = numpy_support.vtk_to_numpy(img.GetPointData().GetScalars())
    return {
        "reader": "VTK %s vtkMetaImageReader (VTK coordinates, no conversion)" % vtk.vtkVersion.GetVTKVersion(),
        "spacing": list(img.GetSpacing()),
        "origin": list(img.GetOrigin()),
        "direction": [[m.GetElement(i, j) for j in range(3)] for i in range(3)],
        "point_1_2_1": p,
        "values": {"sum": int(v.sum()), "min": int(v.min()), "max": int(v.max())},
    }


def dump_json(obj, path):
    text = json.dumps(obj, indent=1)
    text = re.sub(r"\[\s*([-+0-9.eE,\s]+?)\s*\]", lambda m: "[" + ", ".join(m.group(1).split()).replace(",,", ",") + "]", text)
    with open(path, "w") as f:
        f.write(text + "\n")


def main():
    os.chdir(HERE)
    write_all()
    data_files = {
        "list.mhd": ["list-z0.raw", "list-z1.raw"],
        "pattern.mhd": ["slice001.raw", "slice002.raw"],
        "orientation-lpi.mhd": ["orientation.raw"],
        "orientation-lpi-oblique.mhd": ["orientation.raw"],
        # written by make_metaimage.py (SimpleITK), read here only
        "oblique.mhd": ["oblique.raw"],
        "oblique.mha": [],
        "oblique-zlib.mha": [],
    }
    files = {}
    for name, parts in data_files.items():
        itk = from_sitk(name)
        assert itk["values"]["sum"] == int(VALUES.sum())
        files[name] = {
            "bytes": {n: os.path.getsize(n) for n in [name] + parts},
            "size": [NX, NY, NZ],
            "stored_type": "int16 little-endian (MET_SHORT)",
            "values": itk["values"],
            "value_at_1_2_1": itk["value_at_1_2_1"],
            "geometry": {"simpleitk": itk, "vtk": from_vtk(name)},
        }
    ref = {
        "convention": "dims [nx, ny, nz], x fastest; world point of index (i,j,k) = origin + D * "
                      "(spacing * (i,j,k)); direction rows are the rows of D; the simpleitk entries are "
                      "RAS (ITK's LPS with x and y negated), the vtk entries are VTK's own coordinates",
        "written_by": "make_metaimage_list.py (headers by hand) and make_metaimage.py (SimpleITK 2.5.7)",
        "note": "SimpleITK ignores AnatomicalOrientation; VTK 9.7.2's vtkMetaImageReader reads TransformMatrix "
                "transposed relative to SimpleITK (its direction = ITK's direction transposed)",
        "files": files,
    }
    dump_json(ref, "reference.json")
    for n, d in files.items():
        g = d["geometry"]
        print(n, d["bytes"], "RAS (1,2,1):", np.round(g["simpleitk"]["point_1_2_1"], 6).tolist(),
              "VTK:", np.round(g["vtk"]["point_1_2_1"], 6).tolist())


if __name__ == "__main__":
    main()
