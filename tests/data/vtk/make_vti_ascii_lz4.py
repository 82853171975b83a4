"""Writes the ASCII and LZ4-compressed `.vti` test files in this folder with VTK's
vtkXMLImageDataWriter and records reference geometry from vtkXMLImageDataReader.

Volume: 4x3x2 points, one Int16 point-data array "density" with values 5 i - 30 for point id
i = x + 4 (y + 3 z), spacing (0.5, 0.75, 2), origin (10, -20, 30) and an oblique, non-symmetric
direction R = Rx(20 deg) @ Rz(30 deg) (columns: the directions of index axes x, y, z), which
VTK >= 9 writes as the `Direction` attribute (row-major, 9 numbers).

Files:
  vtk-ascii.vti                 SetDataModeToAscii (no compression applies)
  vtk-appended-raw-lz4.vti      appended raw binary (EncodeAppendedDataOff), LZ4, one block
  vtk-appended-base64-lz4.vti   appended base64 (EncodeAppendedDataOn), LZ4, block size 32 bytes,
                                so the 48 bytes of data are two blocks (32 + 16)
  vtk-binary-lz4.vti            inline binary (SetDataModeToBinary, always base64), LZ4,
                                block size 32 bytes (two blocks)

reference.json also lists the two files make_vti.py writes (5x4x3, identity direction), read
here without being rewritten.

VTK image data has no patient frame: reference.json gives VTK's own coordinates as its reader
returns them (vtkImageData origin, spacing, direction matrix, TransformIndexToPhysicalPoint), with
no LPS/RAS conversion.

Made with Python 3.11, numpy 2.4.6, VTK 9.7.2 (pip install numpy vtk).
Run from anywhere: python3 make_vti_ascii_lz4.py
"""
import json
import math
import os
import re

import numpy as np
import vtk
from vtk.util import numpy_support

HERE = os.path.dirname(os.path.abspath(__file__))
NX, NY, NZ = 4, 3, 2
SPACING = (0.5, 0.75, 2.0)
ORIGIN = (10.0, -20.0, 30.0)
PROBE = (1, 2, 1)


def rot(axis, deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


R = rot("x", 20) @ rot("z", 30)
VALUES = (np.arange(NX * NY * NZ, dtype=np.int16) * 5 - 30).astype(np.int16)  # x fastest


LAYOUT = {
    "vtk-ascii.vti": "inline ascii",
    "vtk-appended-raw-lz4.vti": "appended raw: '_' then UInt32 header [1 block, block size 32768, last "
                                "block 48, compressed size] then the LZ4 block",
    "vtk-appended-base64-lz4.vti": "appended base64: the UInt32 header [2 blocks, 32, 16, sizes] is base64 "
                                   "on its own (ends in '='), then the LZ4 blocks as one base64 run",
    "vtk-binary-lz4.vti": "inline base64 in the DataArray, header and blocks encoded separately as above",
    # Written by make_vti.py (5x4x3, no direction, a second array); read here only.
    "vtk-appended-zlib.vti": "written by make_vti.py: appended base64, zlib",
    "vtk-appended-base64.vti": "written by make_vti.py: appended base64, uncompressed",
}


def image():
    img = vtk.vtkImageData()
    img.SetDimensions(NX, NY, NZ)
    img.SetSpacing(*SPACING)
    img.SetOrigin(*ORIGIN)
    img.SetDirectionMatrix(*R.ravel())  # row-major
    arr = numpy_support.numpy_to_vtk(VALUES, deep=1, array_type=vtk.VTK_SHORT)
    arr.SetName("density")
    img.GetPointData().SetScalars(arr)
    return img


def write(name, mode, lz4, encode_appended=True, block_size=None):
    w = vtk.vtkXMLImageDataWriter()
    w.SetFileName(os.path.join(HERE, name))
    w.SetInputData(image())
    if mode == "ascii":
        w.SetDataModeToAscii()
    elif mode == "binary":
        w.SetDataModeToBinary()
    else:
        w.SetDataModeToAppended()
        w.SetEncodeAppendedData(1 if encode_appended else 0)
    if lz4:
        w.SetCompressorTypeToLZ4()
    else:
        w.SetCompressorTypeToNone()
    if block_size:
        w.SetBlockSize(block_size)
    assert w.Write() == 1


def describe(name):
    r = vtk.vtkXMLImageDataReader()
    r.SetFileName(name)
    r.Update()
    img = r.GetOutput()
    v = numpy_support.vtk_to_numpy(img.GetPointData().GetArray("density"))
    m = img.GetDirectionMatrix()
    d = [[m.GetElement(i, j) for j in range(3)] for i in range(3)]
    p = [0.0, 0.0, 0.0]
    img.TransformIndexToPhysicalPoint(*PROBE, p)
    text = open(name, "rb").read()
    head = text[: text.find(b"<ImageData")]
    return {
        "bytes": os.path.getsize(name),
        "vtkfile_attributes": re.search(rb"<VTKFile[^>]*>", head).group(0).decode(),
        "size": list(img.GetDimensions()),
        "stored_type": "Int16 little-endian",
        "layout": LAYOUT[name],
        "values": {"sum": int(v.sum()), "min": int(v.min()), "max": int(v.max())},
        "value_at_1_2_1": int(v[img.ComputePointId(PROBE)]),
        "geometry": {
            "vtk": {
                "reader": "VTK %s vtkXMLImageDataReader (VTK coordinates, no LPS/RAS conversion)"
                          % vtk.vtkVersion.GetVTKVersion(),
                "spacing": list(img.GetSpacing()),
                "origin": list(img.GetOrigin()),
                "direction": d,
                "point_1_2_1": p,
            }
        },
    }


def dump_json(obj, path):
    text = json.dumps(obj, indent=1)
    text = re.sub(r"\[\s*([-+0-9.eE,\s]+?)\s*\]", lambda m: "[" + ", ".join(m.group(1).split()).replace(",,", ",") + "]", text)
    with open(path, "w") as f:
        f.write(text + "\n")


def main():
    os.chdir(HERE)
    write("vtk-ascii.vti", "ascii", lz4=False)
    write("vtk-appended-raw-lz4.vti", "appended", lz4=True, encode_appended=False)
    write("vtk-appended-base64-lz4.vti", "appended", lz4=True, encode_appended=True, block_size=32)
    write("vtk-binary-lz4.vti", "binary", lz4=True, block_size=32)
    names = ["vtk-ascii.vti", "vtk-appended-raw-lz4.vti", "vtk-appended-base64-lz4.vti", "vtk-binary-lz4.vti"]
    names += ["vtk-appended-zlib.vti", "vtk-appended-base64.vti"]  # from make_vti.py, for reference only
    files = {n: describe(n) for n in names}
    ref = {
        "convention": "dims [nx, ny, nz], x fastest; point of index (i,j,k) = origin + D * "
                      "(spacing * (i,j,k)); direction rows are the rows of D (VTK's Direction "
                      "attribute, row-major); VTK's own coordinates, no patient frame, no LPS/RAS conversion",
        "written_by": "VTK %s vtkXMLImageDataWriter (make_vti_ascii_lz4.py)" % vtk.vtkVersion.GetVTKVersion(),
        "files": files,
    }
    dump_json(ref, "reference.json")
    for n, d in files.items():
        print(n, d["bytes"], "bytes", d["geometry"]["vtk"]["point_1_2_1"], d["values"])


if __name__ == "__main__":
    main()
