"""Writes the MetaImage test files with SimpleITK (pip install SimpleITK; 2.5.7 made these):
a 4x3x2 int16 volume, values 5 i - 30 for voxel id i, spacing 0.5, 0.75, 2, origin
(10, -20, 30) and an oblique, non-symmetric direction (30 degrees about z, then 20 about x),
as .mha, compressed .mha and .mhd with its .raw. Prints the physical (LPS) point of index
(1, 2, 1), which tests/volume_formats.rs checks."""
import math

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
sitk.WriteImage(im, "oblique.mha")
sitk.WriteImage(im, "oblique-zlib.mha", useCompression=True)
sitk.WriteImage(im, "oblique.mhd")
print(im.TransformIndexToPhysicalPoint((1, 2, 1)))
