"""Writes legacy `.vtk` STRUCTURED_POINTS test files in this folder with VTK's own
vtkStructuredPointsWriter and records what vtkStructuredPointsReader and SimpleITK read from them
in legacy-reference.json.

Volume: 4x3x2 points, one point-data scalar array "density", origin (10, -20, 30):

  legacy-ascii.vtk                   short, values 5 i - 30, spacing (0.5, 0.75, 2), ASCII
  legacy-negative-spacing.vtk        short, values 5 i - 30, spacing (0.5, -0.75, 2), BINARY
                                     (legacy binary is big-endian)
  legacy-negative-spacing-ascii.vtk  short, values 5 i - 30, spacing (-0.5, 0.75, 2), ASCII
  legacy-ascii-float.vtk             float, values 0.25 i - 3, spacing (1, 1, 1), ASCII

for point id i = x + 4 (y + 3 z). VTK keeps a negative spacing as given: it is written to the
SPACING line and the reader returns it unchanged, so VTK's point of index (i,j,k) is
origin + spacing * (i,j,k) with the signed spacing. SimpleITK (ITK's VTKImageIO) returns positive
spacing and flips the sign of the matching column of its direction matrix instead; its
TransformIndexToPhysicalPoint lands on the same point.

Legacy VTK has no patient frame: legacy-reference.json gives VTK's own coordinates for both
readers, with no LPS/RAS conversion.

Made with Python 3.11, numpy 2.4.6, VTK 9.7.2, SimpleITK 2.5.7
(pip install numpy vtk SimpleITK). Run from anywhere: python3 make_vtk_legacy.py
"""
import json
import os
import re

import numpy as np
import SimpleITK as sitk
import vtk
from vtk.util import numpy_support

HERE = os.path.dirname(os.path.abspath(__file__))
NX, NY, NZ = 4, 3, 2
ORIGIN = (10.0, -20.0, 30.0)
PROBE = (1, 2, 1)
SHORTS = (np.arange(NX * NY * NZ, dtype=np.int16) * 5 - 30).astype(np.int16)  # x fastest
FLOATS = (np.arange(NX * NY * NZ) * 0.25 - 3).astype(np.float32)

# name -> (ascii?, spacing, values, VTK array type)
FILES = {
    "legacy-ascii.vtk": (True, (0.5, 0.75, 2.0), SHORTS, vtk.VTK_SHORT),
    "legacy-negative-spacing.vtk": (False, (0.5, -0.75, 2.0), SHORTS, vtk.VTK_SHORT),
    "legacy-negative-spacing-ascii.vtk": (True, (-0.5, 0.75, 2.0), SHORTS, vtk.VTK_SHORT),
    "legacy-ascii-float.vtk": (True, (1.0, 1.0, 1.0), FLOATS, vtk.VTK_FLOAT),
}


def image(spacing, values, array_type):
    img = vtk.vtkImageData()
    img.SetDimensions(NX, NY, NZ)
    img.SetSpacing(*spacing)
    img.SetOrigin(*ORIGIN)
    arr = numpy_support.numpy_to_vtk(values, deep=1, array_type=array_type)
    arr.SetName("density")
    img.GetPointData().SetScalars(arr)
    return img


def write(name):
    ascii, spacing, values, array_type = FILES[name]
    w = vtk.vtkStructuredPointsWriter()
    w.SetFileName(os.path.join(HERE, name))
    w.SetInputData(image(spacing, values, array_type))
    if ascii:
        w.SetFileTypeToASCII()
    else:
        w.SetFileTypeToBinary()
    assert w.Write() == 1


def num(x, is_float):
    return float(x) if is_float else int(x)


def stats(v, is_float):
    return {"sum": num(v.sum(), is_float), "min": num(v.min(), is_float), "max": num(v.max(), is_float)}


def header_text(name):
    """The header lines, up to and including `LOOKUP_TABLE default`."""
    text = open(name, "rb").read()
    end = text.index(b"LOOKUP_TABLE default") + len(b"LOOKUP_TABLE default")
    return text[:end].decode("ascii").splitlines()


def from_vtk(name, is_float):
    r = vtk.vtkStructuredPointsReader()
    r.SetFileName(name)
    r.Update()
    img = r.GetOutput()
    s = img.GetPointData().GetScalars()
    v = numpy_support.vtk_to_numpy(s)
    m = img.GetDirectionMatrix()
    point = (np.array(img.GetOrigin()) + np.array(img.GetSpacing()) * np.array(PROBE)).tolist()
    t = [0.0, 0.0, 0.0]
    img.TransformIndexToPhysicalPoint(*PROBE, t)
    assert np.allclose(point, t)
    return v, {
        "reader": "VTK %s vtkStructuredPointsReader (VTK coordinates, no LPS/RAS conversion)"
                  % vtk.vtkVersion.GetVTKVersion(),
        "file_version": "%d.%d" % (r.GetFileMajorVersion(), r.GetFileMinorVersion()),
        "size": list(img.GetDimensions()),
        "spacing": list(img.GetSpacing()),
        "origin": list(img.GetOrigin()),
        "direction": [[m.GetElement(i, j) for j in range(3)] for i in range(3)],
        "scalar_type": s.GetDataTypeAsString(),
        "scalar_name": s.GetName(),
        "values": stats(v, is_float),
        "value_at_1_2_1": num(v[img.ComputePointId(PROBE)], is_float),
        "point_1_2_1": point,
    }


def from_sitk(name, is_float):
    try:
        im = sitk.ReadImage(name)
    except RuntimeError as e:
        return None, {"reader": "SimpleITK %s" % sitk.Version.VersionString(),
                      "error": str(e).strip().splitlines()[-1]}
    v = sitk.GetArrayFromImage(im)  # (z, y, x)
    d = im.GetDirection()
    return v, {
        "reader": "SimpleITK %s (VTK coordinates as ITK reads them, no LPS/RAS conversion)"
                  % sitk.Version.VersionString(),
        "size": list(im.GetSize()),
        "spacing": list(im.GetSpacing()),
        "origin": list(im.GetOrigin()),
        "direction": [list(d[0:3]), list(d[3:6]), list(d[6:9])],
        "pixel_type": im.GetPixelIDTypeAsString(),
        "values": stats(v, is_float),
        "value_at_1_2_1": num(v[PROBE[2], PROBE[1], PROBE[0]], is_float),
        "point_1_2_1": list(im.TransformIndexToPhysicalPoint(PROBE)),
    }


def dump_json(obj, path):
    text = json.dumps(obj, indent=1)
    text = re.sub(r"\[\s*([-+0-9.eE,\s]+?)\s*\]", lambda m: "[" + ", ".join(m.group(1).split()).replace(",,", ",") + "]", text)
    with open(path, "w") as f:
        f.write(text + "\n")


def main():
    os.chdir(HERE)
    files = {}
    for name, (ascii, spacing, values, array_type) in FILES.items():
        write(name)
        is_float = array_type == vtk.VTK_FLOAT
        v_vtk, g_vtk = from_vtk(name, is_float)
        v_itk, g_itk = from_sitk(name, is_float)
        assert np.array_equal(v_vtk, values)
        assert g_vtk["spacing"] == list(spacing)  # negative spacing kept as written
        same_point = same_value = None
        if v_itk is not None:
            assert np.array_equal(v_itk.ravel(), values)
            same_point = bool(np.allclose(g_vtk["point_1_2_1"], g_itk["point_1_2_1"]))
            same_value = g_vtk["value_at_1_2_1"] == g_itk["value_at_1_2_1"]
        files[name] = {
            "bytes": os.path.getsize(name),
            "file_type": "ASCII" if ascii else "BINARY",
            "header": header_text(name),
            "size": [NX, NY, NZ],
            "stored_type": ("float" if is_float else "short") + (" ascii" if ascii else " big-endian"),
            "values": stats(values, is_float),
            "value_at_1_2_1": g_vtk["value_at_1_2_1"],
            "geometry": {"vtk": g_vtk, "simpleitk": g_itk},
            "readers_agree_on_point_1_2_1": same_point,
            "readers_agree_on_value_at_1_2_1": same_value,
        }
    ref = {
        "convention": "dims [nx, ny, nz], x fastest; VTK: point of index (i,j,k) = origin + spacing * "
                      "(i,j,k) with the spacing as written, negative components kept (legacy "
                      "STRUCTURED_POINTS has no direction; the reader's direction is the identity); "
                      "SimpleITK: point of index (i,j,k) = origin + D * (spacing * (i,j,k)), spacing "
                      "positive, direction rows are the rows of D; VTK's own coordinates, legacy VTK has "
                      "no patient frame, no LPS/RAS conversion",
        "written_by": "VTK %s vtkStructuredPointsWriter (make_vtk_legacy.py)" % vtk.vtkVersion.GetVTKVersion(),
        "files": files,
    }
    dump_json(ref, "legacy-reference.json")
    for n, d in files.items():
        g = d["geometry"]
        print(n, d["bytes"], "bytes; VTK point (1,2,1):", g["vtk"]["point_1_2_1"], "value", d["value_at_1_2_1"],
              "; SimpleITK:", g["simpleitk"].get("error", g["simpleitk"].get("point_1_2_1")),
              g["simpleitk"].get("value_at_1_2_1"))


if __name__ == "__main__":
    main()
