"""Writes the NIfTI test files in this folder with nibabel and records reference geometry.

Files (all 4x3x2 int16, stored values 5 i - 30 for voxel id i = x + 4 (y + 3 z), with
scl_slope 2 and scl_inter -1, so the scaled values are 2 (5 i - 30) - 1; xyzt_units mm):

  oblique.nii       NIfTI-2 single file (Nifti2Image)
  oblique.nii.gz    the same, gzip-compressed
  sform-qform.nii   NIfTI-1 single file (Nifti1Image) with the same sform and qform
  sform1-qform.nii  NIfTI-1 as above but sform_code 1 instead of 2

The sform (sform_code 2, aligned anatomical; 1 in sform1-qform.nii) is
Rx(20 deg) @ Rz(30 deg) @ diag(0.5, 0.75, 2) with offset (10, -20, 30); the qform
(qform_code 1, scanner anatomical) is a different rotation, Ry(15 deg) @ Rz(-40 deg), with the
same pixdim and offset (-5, 12, 7). Both are RAS, as NIfTI defines them.

reference.json records, per file, the sform- and qform-derived geometry as nibabel's
get_sform() / get_qform() return them, which of the two nibabel's `.affine` takes, and what
SimpleITK reads (converted from ITK's LPS to RAS), or that SimpleITK cannot read the file.

Made with Python 3.11, numpy 2.4.6, nibabel 5.4.2, SimpleITK 2.5.7
(pip install numpy nibabel SimpleITK). Run from anywhere: python3 make_nifti2.py
"""
import json
import math
import os
import re

import nibabel as nib
import numpy as np
import SimpleITK as sitk

HERE = os.path.dirname(os.path.abspath(__file__))
NX, NY, NZ = 4, 3, 2
SPACING = np.array([0.5, 0.75, 2.0])
PROBE = (1, 2, 1)


def rot(axis, deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == "y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def affine(r, origin):
    a = np.eye(4)
    a[:3, :3] = r @ np.diag(SPACING)
    a[:3, 3] = origin
    return a


SFORM = affine(rot("x", 20) @ rot("z", 30), [10.0, -20.0, 30.0])
QFORM = affine(rot("y", 15) @ rot("z", -40), [-5.0, 12.0, 7.0])

# Stored values: array indexed [x, y, z]; nibabel writes it x fastest.
RAW = (np.arange(NX * NY * NZ, dtype=np.int16) * 5 - 30).reshape((NZ, NY, NX)).transpose(2, 1, 0).copy()
SLOPE, INTER = 2.0, -1.0


def geom_from_affine(a, reader):
    """Geometry of a RAS voxel-to-world affine: spacing = column norms, direction columns =
    normalised columns (given as rows of the matrix), origin = translation, probe = a @ (i,j,k,1)."""
    a = np.asarray(a, dtype=float)
    spacing = np.linalg.norm(a[:3, :3], axis=0)
    d = a[:3, :3] / spacing
    p = a @ np.array([*PROBE, 1.0])
    return {
        "reader": reader,
        "spacing": spacing.tolist(),
        "origin": a[:3, 3].tolist(),
        "direction": d.tolist(),
        "point_1_2_1": p[:3].tolist(),
    }


def geom_from_sitk(path):
    try:
        im = sitk.ReadImage(path)
    except RuntimeError as e:
        return {"reader": "SimpleITK %s" % sitk.Version.VersionString(), "error": str(e).strip().splitlines()[-1]}
    flip = np.diag([-1.0, -1.0, 1.0])
    d = flip @ np.array(im.GetDirection()).reshape(3, 3)
    o = flip @ np.array(im.GetOrigin())
    p = flip @ np.array(im.TransformIndexToPhysicalPoint(PROBE))
    v = sitk.GetArrayFromImage(im)
    return {
        "reader": "SimpleITK %s (ITK LPS converted to RAS)" % sitk.Version.VersionString(),
        "spacing": list(im.GetSpacing()),
        "origin": o.tolist(),
        "direction": d.tolist(),
        "point_1_2_1": p.tolist(),
        "pixel_type": im.GetPixelIDTypeAsString(),
        "values": {"sum": float(v.sum()), "min": float(v.min()), "max": float(v.max())},
    }


def write(cls, name, sform_code):
    img = cls(RAW, None)
    img.set_sform(SFORM, code=sform_code)
    img.set_qform(QFORM, code=1)
    img.header.set_xyzt_units(xyz="mm")
    img.header.set_slope_inter(SLOPE, INTER)
    path = os.path.join(HERE, name)
    nib.save(img, path)
    return path


def describe(path):
    img = nib.load(path)
    hdr = img.header
    sform, scode = img.get_sform(coded=True)
    qform, qcode = img.get_qform(coded=True)
    data = img.get_fdata()
    stored = np.asanyarray(img.dataobj.get_unscaled())
    best = "sform" if np.array_equal(img.affine, sform) else ("qform" if np.array_equal(img.affine, qform) else "other")
    sf = geom_from_affine(sform, "nibabel %s get_sform()" % nib.__version__)
    qf = geom_from_affine(qform, "nibabel %s get_qform()" % nib.__version__)
    itk = geom_from_sitk(os.path.basename(path))  # run from HERE, so errors name no directory
    if "origin" in itk:
        itk["takes"] = "sform" if np.allclose(itk["origin"], sf["origin"]) else (
            "qform" if np.allclose(itk["origin"], qf["origin"]) else "other")
    return {
        "bytes": os.path.getsize(path),
        "format": "NIfTI-%d%s" % (2 if isinstance(img, nib.Nifti2Image) else 1,
                                   ", gzip" if path.endswith(".gz") else ""),
        "size": list(img.shape),
        "stored_type": "int16 little-endian",
        "scl_slope": float(img.dataobj.slope),
        "scl_inter": float(img.dataobj.inter),
        "sform_code": int(scode),
        "qform_code": int(qcode),
        "xyzt_units": int(hdr["xyzt_units"]),
        "stored_values": {"sum": int(stored.sum()), "min": int(stored.min()), "max": int(stored.max())},
        "values": {"sum": float(data.sum()), "min": float(data.min()), "max": float(data.max()),
                   "note": "after scaling, value = 2 * stored - 1"},
        "value_at_1_2_1": float(data[PROBE]),
        "nibabel_affine_takes": best,
        "geometry": {"sform": sf, "qform": qf, "simpleitk": itk},
    }


def dump_json(obj, path):
    """json.dump with lists of numbers kept on one line."""
    text = json.dumps(obj, indent=1)
    text = re.sub(r"\[\s*([-+0-9.eE,\s]+?)\s*\]", lambda m: "[" + ", ".join(m.group(1).split()).replace(",,", ",") + "]", text)
    with open(path, "w") as f:
        f.write(text + "\n")


def main():
    os.chdir(HERE)
    files = {}
    p = write(nib.Nifti2Image, "oblique.nii", 2)
    files["oblique.nii"] = describe(p)
    # nibabel writes .nii.gz through gzip; mtime is fixed so the file is reproducible.
    files["oblique.nii.gz"] = describe(write(nib.Nifti2Image, "oblique.nii.gz", 2))
    files["sform-qform.nii"] = describe(write(nib.Nifti1Image, "sform-qform.nii", 2))
    files["sform1-qform.nii"] = describe(write(nib.Nifti1Image, "sform1-qform.nii", 1))
    ref = {
        "convention": "dims [nx, ny, nz], x fastest; world point of index (i,j,k) = origin + D * "
                      "(spacing * (i,j,k)); direction rows are the rows of D (its columns are the axis "
                      "directions); all coordinates RAS",
        "written_by": "nibabel %s (make_nifti2.py)" % nib.__version__,
        "files": files,
    }
    dump_json(ref, os.path.join(HERE, "reference.json"))
    for name, d in files.items():
        print(name, d["bytes"], "bytes; nibabel affine takes", d["nibabel_affine_takes"],
              "; SimpleITK:", d["geometry"]["simpleitk"].get("takes", d["geometry"]["simpleitk"].get("error")))


if __name__ == "__main__":
    main()
