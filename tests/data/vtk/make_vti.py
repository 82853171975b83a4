import vtk
from vtk.util import numpy_support
import numpy as np
nx, ny, nz = 5, 4, 3
vals = (np.arange(nx*ny*nz, dtype=np.int16) * 7 - 100).astype(np.int16)
img = vtk.vtkImageData()
img.SetDimensions(nx, ny, nz)
img.SetSpacing(0.5, 0.75, 2.0)
img.SetOrigin(-10.0, 20.0, 5.5)
arr = numpy_support.numpy_to_vtk(vals, deep=1, array_type=vtk.VTK_SHORT)
arr.SetName("density")
img.GetPointData().SetScalars(arr)
extra = numpy_support.numpy_to_vtk(np.ones(nx*ny*nz, dtype=np.float32), deep=1)
extra.SetName("ones")
img.GetPointData().AddArray(extra)
for name, compress in [("vtk-appended-zlib", True), ("vtk-appended-base64", False)]:
    w = vtk.vtkXMLImageDataWriter()
    w.SetFileName(f"{name}.vti")
    w.SetInputData(img)
    w.EncodeAppendedDataOn()
    if not compress:
        w.SetCompressorTypeToNone()
    w.Write()
