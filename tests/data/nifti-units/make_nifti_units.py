"""Writes NIfTI-1 files whose lengths are in micrometres and in metres with nibabel (pip
install nibabel SimpleITK; nibabel 5.4.2 and SimpleITK 2.5.7 made these): a 4x3x2 int16 volume
(values 5 i - 30 for voxel id i) with an oblique, non-symmetric sform (Rx(20 deg) Rz(30 deg),
steps 500, 750 and 2000 um, or 0.0005, 0.00075 and 0.002 m; origin (10, -20, 30) mm in the
file's unit) and the same qform. reference.json records, for each file, nibabel's affine (in the
file's unit: nibabel leaves units alone) and that affine in millimetres, and SimpleITK's
geometry (RAS), for the test to compare with what splatscene loads."""
import json
import math

import nibabel as nib
import numpy as np
import SimpleITK as sitk

cz, sz = math.cos(math.radians(30)), math.sin(math.radians(30))
cx, sx = math.cos(math.radians(20)), math.sin(math.radians(20))
rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
rotation = rx @ rz
data = (np.arange(24, dtype=np.int16) * 5 - 30).reshape((2, 3, 4)).transpose(2, 1, 0)

reference = {
    "convention": "world point of index (i,j,k) = origin + D * (spacing * (i,j,k)), RAS millimetres; direction rows are the rows of D",
    "written_by": f"make_nifti_units.py (nibabel {nib.__version__}, SimpleITK {sitk.Version_VersionString()})",
    "files": {},
}
for name, unit, to_mm in [("micrometres.nii", "micron", 1e-3), ("metres.nii", "meter", 1e3)]:
    steps = np.array([0.5, 0.75, 2.0]) / to_mm
    affine = np.eye(4)
    affine[:3, :3] = rotation @ np.diag(steps)
    affine[:3, 3] = np.array([10.0, -20.0, 30.0]) / to_mm
    image = nib.Nifti1Image(data, affine)
    image.header.set_xyzt_units(xyz=unit, t="sec")
    image.set_sform(affine, code=2)
    image.set_qform(affine, code=1)
    nib.save(image, name)
    back = nib.load(name)
    mm = back.affine.copy()
    mm[:3, :] *= to_mm
    itk = sitk.ReadImage(name)
    flip = np.diag([-1.0, -1.0, 1.0])
    values = np.asarray(back.dataobj)
    reference["files"][name] = {
        "xyzt_units": back.header.get_xyzt_units()[0],
        "size": list(back.shape),
        "values": {"sum": int(values.sum()), "min": int(values.min()), "max": int(values.max())},
        "value_at_1_2_1": int(values[1, 2, 1]),
        "nibabel_affine_file_units": back.affine.tolist(),
        "geometry": {
            "nibabel_mm": {
                "reader": f"nibabel {nib.__version__} affine, times {to_mm} for millimetres",
                "spacing": list(np.linalg.norm(mm[:3, :3], axis=0)),
                "origin": list(mm[:3, 3]),
                "direction": (mm[:3, :3] / np.linalg.norm(mm[:3, :3], axis=0)).tolist(),
            },
            "simpleitk": {
                "reader": f"SimpleITK {sitk.Version_VersionString()} (ITK LPS converted to RAS)",
                "spacing": list(itk.GetSpacing()),
                "origin": list(flip @ np.array(itk.GetOrigin())),
                "direction": (flip @ np.array(itk.GetDirection()).reshape(3, 3)).tolist(),
            },
        },
    }
with open("reference.json", "w") as f:
    json.dump(reference, f, indent=1)
    f.write("\n")
