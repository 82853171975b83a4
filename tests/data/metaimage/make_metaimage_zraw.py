"""Writes oblique-zraw.mhd with its zlib-compressed data file oblique-zraw.zraw with SimpleITK
(pip install SimpleITK; 2.5.7 made these): the volume of make_metaimage.py, compressed into a
separate data file. Reads it back with SimpleITK and adds its entry to reference.json (sizes,
values, and the geometry in RAS: ITK's LPS with x and y negated)."""
import json
import math
import os

import numpy as np
import SimpleITK as sitk

arr = np.arange(4 * 3 * 2, dtype=np.int16).reshape((2, 3, 4)) * 5 - 30
im = sitk.GetImageFromArray(arr)
im.SetSpacing((0.5, 0.75, 2.0))
im.SetOrigin((10.0, -20.0, 30.0))
cz, sz = math.cos(math.radians(30)), math.sin(math.radians(30))
cx, sx = math.cos(math.radians(20)), math.sin(math.radians(20))
rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
im.SetDirection(tuple((rx @ rz).ravel()))
sitk.WriteImage(im, "oblique-zraw.mhd", useCompression=True)

back = sitk.ReadImage("oblique-zraw.mhd")
values = sitk.GetArrayFromImage(back)
flip = np.diag([-1.0, -1.0, 1.0])
direction = flip @ np.array(back.GetDirection()).reshape(3, 3)
point = flip @ np.array(back.TransformIndexToPhysicalPoint((1, 2, 1)))
entry = {
    "bytes": {f: os.path.getsize(f) for f in ["oblique-zraw.mhd", "oblique-zraw.zraw"]},
    "size": list(back.GetSize()),
    "stored_type": "int16 little-endian (MET_SHORT), zlib-compressed data file",
    "values": {"sum": int(values.sum()), "min": int(values.min()), "max": int(values.max())},
    "value_at_1_2_1": int(values[1, 2, 1]),
    "geometry": {
        "simpleitk": {
            "reader": f"SimpleITK {sitk.Version_VersionString()} (ITK LPS converted to RAS)",
            "size": list(back.GetSize()),
            "spacing": list(back.GetSpacing()),
            "origin": list(flip @ np.array(back.GetOrigin())),
            "direction": direction.tolist(),
            "point_1_2_1": point.tolist(),
        }
    },
}
with open("reference.json") as f:
    reference = json.load(f)
reference["files"]["oblique-zraw.mhd"] = entry
with open("reference.json", "w") as f:
    json.dump(reference, f, indent=1)
    f.write("\n")
