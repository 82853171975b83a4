"""Writes the Analyze 7.5 test files in this folder with nibabel and records reference geometry.

Files (4x3x2 int16, values 5 i - 30 for voxel id i = x + 4 (y + 3 z), pixdim 0.5, 0.75, 2):

  little.hdr + little.img   little-endian header and data (nibabel AnalyzeImage)
  big.hdr + big.img         the same, big-endian header and data (AnalyzeHeader(endianness='>'))

Analyze 7.5 stores no orientation and no origin (nibabel's plain AnalyzeHeader writes neither;
the `orient` byte at offset 252 is 0). reference.json records the geometry two readers derive:

  * nibabel's `.affine` (RAS): x flipped (radiological), y and z not, with the volume centre
    at world 0: diag(-sx, sy, sz) and translation (sx (nx-1)/2, -sy (ny-1)/2, -sz (nz-1)/2).
  * SimpleITK (ITK's NiftiImageIO, which reads Analyze as NIfTI without a transform): origin 0
    and identity direction in ITK's LPS space, converted here to RAS (x and y negated).

The two disagree in y direction and origin (they agree that world x runs against index x).

Made with Python 3.11, numpy 2.4.6, nibabel 5.4.2, SimpleITK 2.5.7
(pip install numpy nibabel SimpleITK). Run from anywhere: python3 make_analyze.py
"""
import json
import os
import re
import struct

import nibabel as nib
import numpy as np
import SimpleITK as sitk

HERE = os.path.dirname(os.path.abspath(__file__))
NX, NY, NZ = 4, 3, 2
SPACING = (0.5, 0.75, 2.0)
PROBE = (1, 2, 1)
RAW = (np.arange(NX * NY * NZ, dtype=np.int16) * 5 - 30).reshape((NZ, NY, NX)).transpose(2, 1, 0).copy()


def geom_from_affine(a, reader):
    a = np.asarray(a, dtype=float)
    spacing = np.linalg.norm(a[:3, :3], axis=0)
    p = a @ np.array([*PROBE, 1.0])
    return {"reader": reader, "spacing": spacing.tolist(), "origin": a[:3, 3].tolist(),
            "direction": (a[:3, :3] / spacing).tolist(), "point_1_2_1": p[:3].tolist()}


def geom_from_sitk(path):
    sitk.ProcessObject.SetGlobalWarningDisplay(False)  # "Analyze file ... deprecated"
    im = sitk.ReadImage(path)
    flip = np.diag([-1.0, -1.0, 1.0])
    v = sitk.GetArrayFromImage(im)
    return {
        "reader": "SimpleITK %s (ITK LPS converted to RAS)" % sitk.Version.VersionString(),
        "itk_lps": {"origin": list(im.GetOrigin()), "direction": np.array(im.GetDirection()).reshape(3, 3).tolist()},
        "spacing": list(im.GetSpacing()),
        "origin": (flip @ np.array(im.GetOrigin())).tolist(),
        "direction": (flip @ np.array(im.GetDirection()).reshape(3, 3)).tolist(),
        "point_1_2_1": (flip @ np.array(im.TransformIndexToPhysicalPoint(PROBE))).tolist(),
        "pixel_type": im.GetPixelIDTypeAsString(),
        "values": {"sum": float(v.sum()), "min": float(v.min()), "max": float(v.max())},
        "value_at_1_2_1": float(v[PROBE[2], PROBE[1], PROBE[0]]),
    }


def write(name, endianness):
    hdr = nib.AnalyzeHeader(endianness=endianness)
    hdr.set_data_dtype(np.int16)
    hdr.set_data_shape(RAW.shape)
    hdr.set_zooms(SPACING)
    nib.save(nib.AnalyzeImage(RAW, None, header=hdr), os.path.join(HERE, name + ".img"))


def describe(name):
    img = nib.load(name + ".hdr")
    data = np.asanyarray(img.dataobj)
    raw = open(name + ".hdr", "rb").read()
    return {
        "files": {name + ".hdr": os.path.getsize(name + ".hdr"), name + ".img": os.path.getsize(name + ".img")},
        "size": list(img.shape),
        "stored_type": "int16 %s-endian" % ("big" if img.header.endianness == ">" else "little"),
        "sizeof_hdr_bytes": raw[:4].hex(),
        "orient_byte_252": raw[252],
        "values": {"sum": int(data.sum()), "min": int(data.min()), "max": int(data.max())},
        "value_at_1_2_1": int(data[PROBE]),
        "geometry": {
            "nibabel": geom_from_affine(img.affine, "nibabel %s AnalyzeImage.affine" % nib.__version__),
            "simpleitk": geom_from_sitk(name + ".hdr"),
        },
    }


def dump_json(obj, path):
    text = json.dumps(obj, indent=1)
    text = re.sub(r"\[\s*([-+0-9.eE,\s]+?)\s*\]", lambda m: "[" + ", ".join(m.group(1).split()).replace(",,", ",") + "]", text)
    with open(path, "w") as f:
        f.write(text + "\n")


def main():
    os.chdir(HERE)
    write("little", "<")
    write("big", ">")
    files = {name: describe(name) for name in ("little", "big")}
    ref = {
        "convention": "dims [nx, ny, nz], x fastest; world point of index (i,j,k) = origin + D * "
                      "(spacing * (i,j,k)); direction rows are the rows of D; all coordinates RAS",
        "written_by": "nibabel %s (make_analyze.py)" % nib.__version__,
        "note": "Analyze 7.5 has no orientation: nibabel and SimpleITK disagree (y direction, origin)",
        "files": files,
    }
    dump_json(ref, "reference.json")
    for name, d in files.items():
        g = d["geometry"]
        print(name, d["files"], d["stored_type"])
        print("  nibabel  ", g["nibabel"]["origin"], g["nibabel"]["point_1_2_1"])
        print("  simpleitk", g["simpleitk"]["origin"], g["simpleitk"]["point_1_2_1"])


if __name__ == "__main__":
    main()
